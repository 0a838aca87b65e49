"""Validation aid for suite crowdnav-classic: CrowdNav's own episode loop, re-implemented from its description, with
pyrvo, to separate what the testbed's env changes from what sampling and the ORCA library change.

It runs the orca robot in CrowdNav's invisible setting with CrowdNav's rules, not the env's: one 0.25 s step per
decision, contact checked once per step on the robot's new velocity against each human's previous velocity, timeout
once 24 s have passed, and CrowdNav's test cases (legacy numpy seeding, 1000 + case, humans drawn in CrowdNav's order).
`--env-rules` instead checks contact along the true motions (as the env does) and times out at 25 s.
`--through-env` runs the same cases through the env (suite crowdnav-classic's config, policy orca, the crowd's
circle crossing swapped for CrowdNav's cases) and counts the cases whose outcome differs from the `--env-rules` loop.

    python scripts/crowdnav_orca_check.py --cases 500 [--env-rules | --through-env]
"""

from __future__ import annotations

import argparse

import numpy as np

from envs.crowds.rvo import OrcaParams, orca_velocities, pref_velocity

R, V, GAP, CIRCLE, DT = 0.3, 1.0, 0.2, 4.0, 0.25


def seg_point_dist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance (N,) from the origin to segments a -> b (N, 2)."""
    d = b - a
    t = np.clip(-(a * d).sum(1) / np.maximum((d * d).sum(1), 1e-12), 0.0, 1.0)
    return np.linalg.norm(a + t[:, None] * d, axis=1)


def case(seed: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """CrowdNav's circle crossing test case `seed`: human starts (n, 2), the goals are their opposites."""
    rs = np.random.RandomState(seed)
    starts, goals = [np.array([0.0, -CIRCLE])], [np.array([0.0, CIRCLE])]
    for _ in range(n):
        while True:
            a = rs.random_sample() * 2 * np.pi
            nx, ny = (rs.random_sample() - 0.5) * V, (rs.random_sample() - 0.5) * V
            p = CIRCLE * np.array([np.cos(a), np.sin(a)]) + [nx, ny]
            if all(np.linalg.norm(p - s) >= 2 * R + GAP and np.linalg.norm(p - g) >= 2 * R + GAP
                   for s, g in zip(starts, goals, strict=True)):
                break
        starts.append(p)
        goals.append(-p)
    return np.array(starts[1:]), np.array(goals[1:])


def episode(seed: int, n: int, env_rules: bool) -> tuple[str, float]:
    params = OrcaParams()
    hp, hg = case(seed, n)
    hv = np.zeros((n, 2))
    rp, rg, rv = np.array([0.0, -CIRCLE]), np.array([0.0, CIRCLE]), np.zeros(2)
    t = 0.0
    limit = 25.0 if env_rules else 24.0
    while True:
        pos, vel = np.vstack([rp, hp]), np.vstack([rv, hv])
        pref = np.zeros((n + 1, 2))
        pref[0] = pref_velocity(rp[None], rg[None], np.array([V]))[0]
        new_rv = orca_velocities(pos, vel, pref, np.full(n + 1, R), np.full(n + 1, V), params)[0]
        new_hv = orca_velocities(hp, hv, pref_velocity(hp, hg, np.full(n, V)), np.full(n, R), np.full(n, V), params)
        rel0 = hp - rp
        rel1 = rel0 + DT * ((new_hv if env_rules else hv) - new_rv)
        collided = bool(np.any(seg_point_dist(rel0, rel1) < 2 * R))
        reached = np.linalg.norm(rp + DT * new_rv - rg) < R
        if not env_rules and t >= limit - 1e-9:
            return "timeout", t
        if collided:
            return "collision", t
        if reached:
            return "success", t + DT
        rp, rv, hp, hv = rp + DT * new_rv, new_rv, hp + DT * new_hv, new_hv
        t += DT
        if env_rules and t >= limit - 1e-9:
            return "timeout", t


def through_env(cases: int, n: int) -> list[tuple[str, float]]:
    """The cases run by the env; prints how many outcomes differ from CrowdNav's loop under the env's rules."""
    from envs.crowds.orca import OrcaCrowd
    from envs.env import CrowdNavEnv
    from envs.evaluation.suite import load_suite
    from envs.policies import decide, make_policy

    now = {"case": 0}
    OrcaCrowd._circle_crossing = lambda self: case(now["case"], self.n)  # validation only: CrowdNav's test cases
    env = CrowdNavEnv(load_suite("crowdnav-classic").cells[0].env_config(0))
    policy = make_policy("orca", env)
    res, differ = [], 0
    for i in range(cases):
        now["case"] = 1000 + i
        env.reset(seed=i)
        policy.reset(i)
        done = False
        while not done:
            _, _, term, trunc, info = env.step_decision(decide(policy, env))
            done = term or trunc
        m = info["episode_metrics"]
        res.append((m["outcome"], m["time_s"]))
        differ += m["outcome"] != episode(1000 + i, n, True)[0]
    print(f"through the env: {differ} of {cases} outcomes differ from CrowdNav's loop under the env's rules")
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cases", type=int, default=500)
    ap.add_argument("--humans", type=int, default=5)
    ap.add_argument("--env-rules", action="store_true")
    ap.add_argument("--through-env", action="store_true")
    args = ap.parse_args()
    if args.through_env:
        res = through_env(args.cases, args.humans)
    else:
        res = [episode(1000 + i, args.humans, args.env_rules) for i in range(args.cases)]
    outcomes = [o for o, _ in res]
    times = [t for o, t in res if o == "success"]
    k = len(res)
    print(f"{k} cases: success {outcomes.count('success') / k:.3f}, collision {outcomes.count('collision') / k:.3f}, "
          f"timeout {outcomes.count('timeout') / k:.3f}, time to goal {np.mean(times):.2f} s")


if __name__ == "__main__":
    main()
