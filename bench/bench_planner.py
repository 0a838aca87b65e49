"""Closed-loop solve-time benchmark of the MPC planner in a synthetic moving crowd.

The crowd is generated here with numpy (no crowdsim): constant-velocity walkers, 40% of them in
pairs walking abreast, bouncing off the walls of a 16 m x 10 m hall, none spawned within 2 m of the
robot. The robot shuttles between
two goals 12 m apart through the crowd. Each step it gets a 20-sample prediction (constant velocity
with a random heading and speed per sample, shared by the members of a pair), plans, and applies the
first control for one plan step. Pedestrians do not react to the robot.

Reports per (solver, pedestrians, K): solver wall time p50/p95/max; plan() wall time p50 (solve plus
pre-processing); plan() CPU time p50/p95 (robust to other processes sharing the CPU); deadline misses
(plan() wall time over the plan step); fallback rate; steps in collision (robot body overlapping a
pedestrian's); steps in a pair's region (robot body overlapping the capsule spanning a pair,
collisions with its members included); goals reached.

    python bench/bench_planner.py            # 300 steps per configuration, a few minutes
    python bench/bench_planner.py --quick    # 40 steps per configuration
    python bench/bench_planner.py --crowd    # the env's planner.CROWD_MPC at max_peds 8 and 12, side by side
    python bench/bench_planner.py --guidance # CROWD_MPC without and with the guidance layer (1 and 2 paths)
    python bench/bench_planner.py --foresight # CROWD_MPC without and with the foresight search
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, replace

import numpy as np

from planner import CROWD_MPC, ForesightConfig, GuidanceConfig, MPCConfig, MPCPlanner, PedPrediction, step_robot

HALL_M = np.array([[-2.0, -5.0], [14.0, 5.0]])  # lower-left, upper-right corners
GOALS = np.array([[0.0, 0.0], [12.0, 0.0]])
PED_RADIUS_M = 0.3
N_SAMPLES = 20
PRED_STEPS = 12
PRED_DT_S = 0.4
SPAWN_CLEAR_M = 2.0


@dataclass
class Crowd:
    """Walkers: pos (N, 2) m, vel (N, 2) m/s, group (N,) int."""

    pos: np.ndarray
    vel: np.ndarray
    group: np.ndarray

    @staticmethod
    def make(n: int, rng: np.random.Generator) -> Crowd:
        n_pairs = int(0.2 * n)
        lo, hi = HALL_M[0] + 0.5, HALL_M[1] - 0.5
        pos, vel, group = [], [], []
        for gid in range(n - n_pairs):
            heading, speed = rng.uniform(-np.pi, np.pi), rng.normal(1.1, 0.2)
            v = speed * np.array([np.cos(heading), np.sin(heading)])
            p = rng.uniform(lo, hi)
            while np.linalg.norm(p - GOALS[0]) < SPAWN_CLEAR_M:  # not on top of the robot's start
                p = rng.uniform(lo, hi)
            members = 2 if gid < n_pairs else 1
            side = np.array([-v[1], v[0]]) / max(np.linalg.norm(v), 1e-9)
            for j in range(members):
                pos.append(p + (j - 0.5 * (members - 1)) * 0.75 * side)
                vel.append(v)
                group.append(gid)
        return Crowd(np.array(pos), np.array(vel), np.array(group))

    def step(self, dt: float) -> None:
        """Move dt seconds; a group bounces off a wall when any member reaches it."""
        self.pos += self.vel * dt
        for axis in range(2):
            out = (self.pos[:, axis] < HALL_M[0, axis]) | (self.pos[:, axis] > HALL_M[1, axis])
            flip = np.isin(self.group, self.group[out])
            self.vel[flip, axis] *= -1.0

    def pair_segments(self) -> np.ndarray:
        """Segments (P, 4) between the two members of every pair, m."""
        ids, counts = np.unique(self.group, return_counts=True)
        segs = [self.pos[self.group == gid].ravel() for gid in ids[counts == 2]]
        return np.array(segs).reshape(-1, 4)

    def contacts(self, xy: np.ndarray, robot_radius_m: float) -> tuple[bool, bool]:
        """(robot body overlaps a pedestrian, robot body overlaps a pair's capsule region)."""
        reach = robot_radius_m + PED_RADIUS_M
        collision = bool(np.any(np.linalg.norm(self.pos - xy, axis=1) < reach))
        segs = self.pair_segments()
        if len(segs) == 0:
            return collision, False
        a, ab = segs[:, :2], segs[:, 2:] - segs[:, :2]
        t = np.clip(((xy - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-12), 0.0, 1.0)
        intrusion = bool(np.any(np.linalg.norm(a + t[:, None] * ab - xy, axis=1) < reach))
        return collision, intrusion

    def predict(self, rng: np.random.Generator) -> PedPrediction:
        """20 samples of perturbed constant-velocity futures, jointly sampled within a group."""
        n_groups = int(self.group.max()) + 1
        turn = rng.normal(0.0, 0.25, (N_SAMPLES, n_groups))[:, self.group]
        gain = rng.normal(1.0, 0.15, (N_SAMPLES, n_groups))[:, self.group]
        cos, sin = np.cos(turn), np.sin(turn)
        vx = gain * (cos * self.vel[:, 0] - sin * self.vel[:, 1])
        vy = gain * (sin * self.vel[:, 0] + cos * self.vel[:, 1])
        times = PRED_DT_S * np.arange(1, PRED_STEPS + 1)[None, :, None, None]
        positions = self.pos[None, None] + times * np.stack([vx, vy], -1)[:, None]
        n = len(self.pos)
        return PedPrediction(positions, np.full(n, PED_RADIUS_M), self.group.copy(), np.ones(n, bool),
                             current=self.pos.copy(), step_s=PRED_DT_S)


def run_case(solver: str, n_peds: int, k: int, steps: int, seed: int,
             base: MPCConfig | None = None) -> dict[str, float]:
    """One closed-loop run of ``base`` (default: ``MPCConfig()``) with ``solver`` and K = ``k``; the table row."""
    rng = np.random.default_rng(seed)
    cfg = replace(base or MPCConfig(), solver=solver, n_modes=k)
    planner = MPCPlanner(cfg)
    crowd = Crowd.make(n_peds, rng)
    state, goal_idx, goals, collisions, intrusions, wall, cpu = np.zeros(5), 1, 0, 0, 0, [], []
    for _ in range(steps):
        goal = GOALS[goal_idx]
        pred = crowd.predict(rng)
        start, start_cpu = time.perf_counter(), time.process_time()
        result = planner.plan(state, goal, pred)
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
        state = step_robot(state, result.control, cfg.dt_s)
        crowd.step(cfg.dt_s)
        collision, intrusion = crowd.contacts(state[:2], cfg.robot.radius_m)
        collisions, intrusions = collisions + collision, intrusions + intrusion
        if np.linalg.norm(state[:2] - goal) < cfg.robot.radius_m:
            goals, goal_idx = goals + 1, 1 - goal_idx
    summary = planner.stats.summary()
    wall_ms, cpu_ms = np.array(wall) * 1e3, np.array(cpu) * 1e3
    return {"solver": solver, "peds": n_peds, "K": k, "steps": steps, "p50": summary.get("p50_ms", np.nan),
            "p95": summary.get("p95_ms", np.nan), "max": summary.get("max_ms", np.nan),
            "plan_p50": float(np.percentile(wall_ms, 50)), "plan_p95": float(np.percentile(wall_ms, 95)),
            "cpu_p50": float(np.percentile(cpu_ms, 50)),
            "cpu_p95": float(np.percentile(cpu_ms, 95)), "misses": int((wall_ms > cfg.dt_s * 1e3).sum()),
            "fallback": 100 * summary["fallback_rate"], "collisions": collisions, "intrusions": intrusions,
            "goals": goals}


HEADER = ("| solver | peds | K | steps | solve p50 ms | solve p95 ms | solve max ms | plan() p50 ms "
          "| plan() CPU p50 / p95 ms "
          "| misses > 0.4 s | fallback % | steps in collision | steps in a pair's region | goals |")


def format_row(r: dict) -> str:
    return (f"| {r['solver']} | {r['peds']} | {r['K']} | {r['steps']} | {r['p50']:.1f} | {r['p95']:.1f} "
            f"| {r['max']:.1f} | {r['plan_p50']:.1f} | {r['cpu_p50']:.1f} / {r['cpu_p95']:.1f} "
            f"| {r['misses']} | {r['fallback']:.1f} "
            f"| {r['collisions']} | {r['intrusions']} | {r['goals']} |")


def crowd_comparison(steps: int, seed: int) -> None:
    """planner.CROWD_MPC (shield on) with the 8 and the 12 nearest pedestrians constrained, side by side on the
    same crowds: plan() CPU p50/p95 and their ratio (12 / 8)."""
    print(f"CROWD_MPC (fatrop, K = {CROWD_MPC.n_modes}, shield {CROWD_MPC.shield_horizon_s} s), {steps} steps, "
          f"seed {seed}")
    print("| peds | max_peds 8: plan() CPU p50 / p95 ms | max_peds 12: plan() CPU p50 / p95 ms | ratio p50 / p95 "
          "| steps in collision 8 / 12 |")
    print("|---|---|---|---|---|")
    for n_peds in (20, 40, 60):
        a, b = (run_case("fatrop", n_peds, CROWD_MPC.n_modes, steps, seed, replace(CROWD_MPC, max_peds=m))
                for m in (8, 12))
        print(f"| {n_peds} | {a['cpu_p50']:.1f} / {a['cpu_p95']:.1f} | {b['cpu_p50']:.1f} / {b['cpu_p95']:.1f} "
              f"| {b['cpu_p50'] / a['cpu_p50']:.2f} / {b['cpu_p95'] / a['cpu_p95']:.2f} "
              f"| {a['collisions']} / {b['collisions']} |", flush=True)


LAYERS = {  # --guidance / --foresight: CROWD_MPC against itself with the opt-in layer, side by side
    "guidance": {"+ guidance, 1 path": replace(CROWD_MPC, guidance=GuidanceConfig(n_paths=1)),
                 "+ guidance, 2 paths": replace(CROWD_MPC, guidance=GuidanceConfig(n_paths=2))},
    "foresight": {"+ foresight": replace(CROWD_MPC, foresight=ForesightConfig())},
}


def layer_comparison(layer: str, steps: int, seed: int) -> None:
    """planner.CROWD_MPC without and with an opt-in layer (`LAYERS`), side by side on the same crowds: plan() CPU
    p50/p95 and their ratio to CROWD_MPC."""
    print(f"CROWD_MPC (fatrop, K = {CROWD_MPC.n_modes}, shield on) without / with {layer}, {steps} steps, seed {seed}")
    print("| peds | config | plan() CPU p50 / p95 ms | ratio p50 / p95 | plan() wall p95 ms | steps in collision "
          "| goals |")
    print("|---|---|---|---|---|---|---|")
    configs = {"CROWD_MPC": CROWD_MPC, **LAYERS[layer]}
    for n_peds in (20, 40, 60):
        rows = {name: run_case("fatrop", n_peds, cfg.n_modes, steps, seed, cfg) for name, cfg in configs.items()}
        ref = rows["CROWD_MPC"]
        for name, r in rows.items():
            print(f"| {n_peds} | {name} | {r['cpu_p50']:.1f} / {r['cpu_p95']:.1f} | {r['cpu_p50'] / ref['cpu_p50']:.2f}"
                  f" / {r['cpu_p95'] / ref['cpu_p95']:.2f} | {r['plan_p95']:.1f} | {r['collisions']} | {r['goals']} |",
                  flush=True)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="40 steps per configuration")
    parser.add_argument("--steps", type=int, default=300, help="closed-loop steps per configuration")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--crowd", action="store_true", help="only the CROWD_MPC max_peds 8 vs 12 comparison")
    parser.add_argument("--guidance", action="store_true", help="only CROWD_MPC without / with the guidance layer")
    parser.add_argument("--foresight", action="store_true", help="only CROWD_MPC without / with the foresight search")
    args = parser.parse_args(argv)
    steps = 40 if args.quick else args.steps
    for layer in LAYERS:
        if getattr(args, layer):
            layer_comparison(layer, steps, args.seed)
            return
    if args.crowd:
        crowd_comparison(steps, args.seed)
        return
    cfg = MPCConfig()
    print(f"plan step {cfg.dt_s} s, horizon {cfg.horizon_steps} steps, nearest {cfg.max_peds} pedestrians, "
          f"{cfg.max_groups} group slots, {N_SAMPLES} samples -> K modes")
    print(HEADER)
    print("|" + "---|" * (HEADER.count("|") - 1))
    for solver in ("fatrop", "ipopt"):
        for n_peds in (10, 20, 40):
            for k in (1, 3):
                print(format_row(run_case(solver, n_peds, k, steps, args.seed)), flush=True)


if __name__ == "__main__":
    main()
