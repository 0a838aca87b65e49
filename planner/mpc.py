"""The MPC planner: builds the NLP once, solves it every step, and falls back safely on failure."""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from planner.config import MPCConfig
from planner.dynamics import brake_control, clip_control, model_dims, step_numpy
from planner.foresight import ForesightSearch
from planner.guidance import (
    checked_points,
    goal_rollouts,
    guidance_rollouts,
    half_planes,
    keeps_sides,
    passing_sides,
    path_costs,
    ped_gaps,
    pick_options,
    side_map,
)
from planner.ocp import OCP, build_ocp, pack_params, param_slices
from planner.prediction import PedPrediction, current_positions, empty_prediction, validate_prediction
from planner.result import PlanResult, PlanStats
from planner.route import Router
from planner.scene import FAR_M, SceneArrays, build_scene, validate_obstacles
from planner.shield import shield_control

IPOPT_OK = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
HEADING_OFFSETS_RAD = (0.0, -0.6, 0.6, -1.2, 1.2)  # first-guess directions relative to the goal


@dataclass(frozen=True)
class _Try:
    """One solve: the solution w, its outcome (``MPCPlanner._classify``), the solver's status, wall time (s),
    iterations, largest slack (m) and objective (inf where not finite); with guidance, the passing sides of its plan
    (input row -> +1 / -1, planner/guidance.py)."""

    w: np.ndarray
    status: str
    solver_status: str
    elapsed: float
    iters: int
    max_slack: float
    cost: float
    sides: dict[int, int] | None = None


@dataclass(frozen=True)
class _Plan:
    """A stored plan starting at the current step: states (H+1, nz), controls (H, nu); age in steps."""

    states: np.ndarray
    controls: np.ndarray
    age: int


def check_state_goal(state: np.ndarray, goal: np.ndarray, state_dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Return float64 copies of state (state_dim,) and goal (2,); raise ValueError on bad shape or values."""
    state = np.array(state, dtype=float)
    goal = np.array(goal, dtype=float)
    if state.shape != (state_dim,):
        raise ValueError(f"robot_state must have shape ({state_dim},), got {state.shape}")
    if goal.shape != (2,):
        raise ValueError(f"goal must have shape (2,), got {goal.shape}")
    if not (np.all(np.isfinite(state)) and np.all(np.isfinite(goal))):
        raise ValueError("robot_state and goal must be finite (no NaN or inf)")
    return state, goal


def check_inputs(state, goal, prediction, obstacles, state_dim: int, dt_s: float):
    """Validate every plan() input before any solver work; raise ValueError with a clear message. No prediction
    (None) is a prediction of nobody, on the plan's own step `dt_s`."""
    state, goal = check_state_goal(state, goal, state_dim)
    if prediction is None:
        prediction = empty_prediction(1, dt_s)
    elif not isinstance(prediction, PedPrediction):
        raise ValueError(f"prediction must be a PedPrediction or None, got {type(prediction).__name__}")
    else:
        validate_prediction(prediction)
    return state, goal, prediction, validate_obstacles(obstacles)


@lru_cache(maxsize=32)
def shared_ocp(config: MPCConfig) -> OCP:
    """The NLP for ``config``, built once per process and shared by planners with an equal config
    (an OCP is immutable; each planner keeps its own warm start, fallback plan and stats)."""
    return build_ocp(config)


class MPCPlanner:
    """Receding-horizon planner. ``plan()`` validates its inputs (ValueError on bad input), then never
    raises: solver failures, timeouts, NaN and infeasible results fall back to the previous plan
    (shifted) or to braking, and every outcome is counted in ``stats``."""

    def __init__(self, config: MPCConfig | None = None) -> None:
        self.config = config or MPCConfig()
        self.dims = model_dims(self.config.robot.model)
        self.ocp: OCP = shared_ocp(self.config)
        self.stats = PlanStats()
        self._plan: _Plan | None = None
        self._mapped: dict[int, tuple] = {}  # `_maps`
        self._sides: dict[int, int] = {}  # guidance: the passing sides of the last applied plan (input row -> side)
        self._options: list[tuple[np.ndarray, np.ndarray, dict[int, int] | None]] = []  # other solved plans, best first
        self.router = Router(self.config.route, self.config.wall_clearance_m) if self.config.route is not None else None
        fs, robot = self.config.foresight, self.config.robot
        self.foresight = None if fs is None else ForesightSearch(fs, robot.max_speed_mps, robot.radius_m,
                                                                 self.config.wall_clearance_m)

    def reset(self) -> None:
        """Forget the stored plan (warm start and fallback), the passing options and the route; keep the stats."""
        self._plan = None
        self._sides, self._options = {}, []
        if self.router is not None:
            self.router.reset()
        if self.foresight is not None:
            self.foresight.reset()

    def plan(self, robot_state: np.ndarray, goal: np.ndarray, prediction: PedPrediction | None = None,
             obstacles: np.ndarray | list | None = None) -> PlanResult:
        """Plan from robot_state (state_dim,) to goal (2,) m among predicted pedestrians (absolute
        positions, see :class:`PedPrediction`; None = nobody) and obstacles (segments (S, 4) m, or a list
        of polygons (V, 2) m; None = none). Returns the first control and the plan (:class:`PlanResult`).
        Raises ValueError on malformed or non-finite input, before any solver work; never otherwise."""
        called = time.perf_counter()
        state, goal, prediction, obstacles = check_inputs(robot_state, goal, prediction, obstacles,
                                                          self.dims.state_dim, self.config.dt_s)
        if self._plan is not None:
            shifted = self._shift(self._plan)
            self._plan = shifted if shifted.age <= self.config.max_plan_reuse_steps else None
        routed = time.perf_counter()
        try:
            subgoal = self._subgoal(state, goal, prediction, obstacles)
            routed = time.perf_counter() - routed
            result = self._solve(state, subgoal, prediction, obstacles)
            result = replace(result, solve_time_s=result.solve_time_s + routed, subgoal=subgoal)
        except Exception as exc:  # never raise inside the control loop
            result = self._fallback(state, "solver_error", f"{type(exc).__name__}: {exc}", 0.0, 0, np.inf)
        if self.config.shield_horizon_s > 0:
            result = self._shield(result, state, prediction, obstacles)
        result = replace(result, plan_time_s=time.perf_counter() - called)
        self.stats.record(result)
        return result

    def _subgoal(self, state: np.ndarray, goal: np.ndarray, prediction: PedPrediction | None,
                 obstacles: np.ndarray | None) -> np.ndarray:
        """The point the solve heads for: the goal; with a route (``config.route``) and walls, the route's subgoal
        (planner/route.py); with the foresight search (``config.foresight``), a point on its way to that one."""
        subgoal = goal
        if self.router is not None and obstacles is not None and len(obstacles):
            subgoal = self.router.subgoal(state[:2], goal, obstacles)
        if self.foresight is not None:
            subgoal = self.foresight.subgoal(state[:2], subgoal, prediction, obstacles, goal)
        return subgoal

    def _shield(self, result: PlanResult, state, prediction, obstacles) -> PlanResult:
        """``result`` with its first control checked by the safety shield (planner/shield.py); the shield's
        wall time is added to ``solve_time_s``. A shield error keeps the plan's control (never raises)."""
        start = time.perf_counter()
        options = self._options if result.status == "solved" else []
        try:
            verdict = shield_control(state, result.controls, prediction, obstacles, self.config,
                                     np.array([controls for _, controls, _ in options]) if options else None)
        except Exception:  # the plan's own control is still a valid (if unchecked) answer
            return result
        elapsed = time.perf_counter() - start
        if verdict.option >= 0:  # another passing option's plan is safe where the chosen one is not: apply it
            states, controls, sides = options[verdict.option]
            self._plan, self._sides = _Plan(states, controls, 0), sides or {}
            result = replace(result, states=states, controls=controls)
        return replace(result, control=verdict.control, solve_time_s=result.solve_time_s + elapsed,
                       shield_risk=verdict.risk, shielded=verdict.replaced)

    # -- solving -------------------------------------------------------------------------------
    def _solve(self, state, goal, prediction, obstacles) -> PlanResult:
        cfg, ocp = self.config, self.ocp
        scene = build_scene(state, prediction, obstacles, cfg)
        if scene.start_penetration_m > 0.0:  # already overlapping someone: infeasible as posed
            depth = scene.start_penetration_m
            return self._fallback(state, "infeasible", "start in collision", 0.0, 0, depth)
        p = pack_params(ocp.sizes, state, goal, scene)
        tries = [self._solve_from(w0, p) for w0 in self._initial_guesses(state, goal, p, cfg.n_starts)]
        if cfg.guidance is not None:
            tries = self._guided_tries(state, goal, scene, prediction, p, tries)
        elapsed, iters = sum(t.elapsed for t in tries), sum(t.iters for t in tries)
        solved = sorted((t for t in tries if t.status == "solved"), key=self._rank)  # stable: the free solve first
        best = solved[0] if solved else tries[0]
        self._options = []
        if best.status != "solved":
            return self._fallback(state, best.status, best.solver_status, elapsed, iters, best.max_slack)
        w, solver_status, max_slack = best.w, best.solver_status, best.max_slack
        states, controls = w[ocp.layout.z], w[ocp.layout.u]
        self._plan = _Plan(states, controls, 0)
        options: tuple[np.ndarray, ...] = ()
        if cfg.guidance is not None:
            self._sides = best.sides or {}
            self._options = [(t.w[ocp.layout.z], t.w[ocp.layout.u], t.sides) for t in solved[1:]]
            options = tuple(t.w[ocp.layout.z] for t in solved)
        return PlanResult(controls[0].copy(), states, controls, "solved", solver_status, elapsed, iters,
                          max_slack, None, options=options)

    def _rank(self, t: _Try) -> float:
        """A solved plan's cost for the choice: its objective under the free problem, ``hold_discount`` less when it
        keeps the last applied plan's passing sides (guidance only)."""
        gc = self.config.guidance
        if gc is None or t.sides is None or not keeps_sides(t.sides, self._sides):
            return t.cost
        return t.cost * (1.0 - gc.hold_discount)

    def _guided_tries(self, state: np.ndarray, goal: np.ndarray, scene: SceneArrays, prediction: PedPrediction,
                      p: np.ndarray, free: list[_Try]) -> list[_Try]:
        """The free tries with their passing sides, then one guided solve per passing option (planner/guidance.py),
        each judged under the free problem's objective and slacks (``p``)."""
        cfg, ocp, layout = self.config, self.ocp, self.ocp.layout
        now = np.full((ocp.sizes.m, 2), FAR_M) + state[:2]
        now[: scene.ped_index.size] = current_positions(prediction)[scene.ped_index]
        paths, path_controls = guidance_rollouts(state, goal, cfg)
        finite = [bool(np.all(np.isfinite(t.w))) for t in free]
        allstates = np.concatenate([paths, *(t.w[layout.z][None] for t, ok in zip(free, finite, strict=True) if ok)])
        gaps = ped_gaps(checked_points(allstates, ocp.sizes.sub), scene)
        sides = passing_sides(allstates, now, scene, gaps, cfg)
        free_sides = iter(sides[len(paths):])  # one row per finite free try, in order
        out = [replace(t, sides=side_map(next(free_sides), scene.ped_index)) if ok else t
               for t, ok in zip(free, finite, strict=True)]
        costs = path_costs(paths, goal, scene, cfg, gaps[: len(paths)])
        slices = param_slices(ocp.sizes)
        for c in pick_options(costs, sides[: len(paths)], list(sides[len(paths):]), cfg.guidance.n_paths):
            normal, on = half_planes(paths[c], scene, gaps[c], cfg, state[:2])
            guided = p.copy()
            guided[slices["ped_normal"]], guided[slices["ped_side"]] = normal.ravel(), on
            w0 = np.zeros(layout.n)
            w0[layout.z], w0[layout.u] = paths[c], path_controls[c]
            w0[layout.s.ravel()] = ocp.slack_fn(w0, guided).full().ravel()
            t = self._solve_from(w0, guided, guided=True)
            if np.all(np.isfinite(t.w)):
                slack = float(ocp.slack_fn(t.w, p).full().max(initial=0.0))
                cost = float(ocp.cost_fn(t.w, p))
                plan = t.w[layout.z][None]
                plan_sides = passing_sides(plan, now, scene, ped_gaps(checked_points(plan, ocp.sizes.sub), scene),
                                           cfg)[0]
                t = replace(t, max_slack=slack, cost=cost if np.isfinite(cost) else np.inf,
                            sides=side_map(plan_sides, scene.ped_index))
            out.append(t)
        return out

    def _solve_from(self, w0: np.ndarray, p: np.ndarray, guided: bool = False) -> _Try:
        """One solve of the NLP from the initial guess ``w0``, classified (``_classify``); ``guided``: with the guidance
        layer's iteration cap."""
        ocp = self.ocp
        solver = ocp.guided_solver if guided and ocp.guided_solver is not None else ocp.solver
        start = time.perf_counter()
        sol = solver(x0=w0, p=p, lbx=ocp.lbx, ubx=ocp.ubx, lbg=ocp.lbg, ubg=ocp.ubg)
        elapsed = time.perf_counter() - start
        stats = solver.stats()
        w = sol["x"].full().ravel()
        solver_status = str(stats.get("return_status", stats.get("unified_return_status", "")))
        finite = bool(np.all(np.isfinite(w)))
        slack = ocp.slack_fn(w, p).full().reshape(ocp.layout.s.shape) if finite else np.full((1, 1), np.inf)
        status = self._classify(stats, elapsed, finite, float(slack[:2].max(initial=0.0)))
        cost = float(sol["f"]) if finite else np.inf
        return _Try(w, status, solver_status, elapsed, int(stats.get("iter_count", 0)), float(slack.max(initial=0.0)),
                    cost if np.isfinite(cost) else np.inf)

    def _classify(self, stats: dict, elapsed: float, finite: bool, first_slack: float) -> str:
        """Outcome of a solve; ``first_slack`` is the clearance violation (m) at the first planned step."""
        ok = bool(stats.get("success", False)) or stats.get("return_status") in IPOPT_OK
        if not finite:
            return "nan"
        if elapsed > self.config.time_budget_s:
            return "timeout"
        if not ok:
            return "solver_failed"
        if first_slack > self.config.max_slack_m:
            return "infeasible"
        return "solved"

    def _initial_guesses(self, state: np.ndarray, goal: np.ndarray, p: np.ndarray, n: int) -> list[np.ndarray]:
        """The ``n`` cheapest of a few candidate guesses under the NLP's own cost, cheapest first: the shifted
        previous plan (if any) and go-to-goal rollouts aimed straight and at +-HEADING_OFFSETS_RAD from the goal
        direction (this breaks symmetric dead-locks such as a pedestrian right on the path; with n > 1 the
        rollouts pass people on different sides). Slacks are set to their minimal feasible values, which fatrop
        needs. NaN and inf costs never win; if none is finite, the last candidate alone."""
        layout = self.ocp.layout
        offsets = np.array(HEADING_OFFSETS_RAD)
        states, controls = goal_rollouts(state, goal, offsets, np.full(offsets.size, self.config.robot.max_speed_mps),
                                         self.config)
        candidates = list(zip(states, controls, strict=True))
        if self._plan is not None:
            prev_states = self._plan.states.copy()
            prev_states[0] = state
            candidates.insert(0, (prev_states, self._plan.controls))
        w = np.zeros((layout.n, len(candidates)))  # one column per candidate, all evaluated in one call each
        for j, (cand_states, cand_controls) in enumerate(candidates):
            w[layout.z, j], w[layout.u, j] = cand_states, cand_controls
        slack_map, cost_map = self._maps(len(candidates))
        w[layout.s.ravel()] = slack_map(w, p).full()
        cost = cost_map(w, p).full().ravel()
        finite = cost < np.inf
        if not finite.any():
            return [w[:, -1].copy()]
        order = np.argsort(np.where(finite, cost, np.inf), kind="stable")[: min(n, int(finite.sum()))]
        return [w[:, j].copy() for j in order]

    def _maps(self, n: int) -> tuple:
        """The NLP's slack and cost functions over n candidate columns (`casadi.Function.map`: the same operations
        column by column, so the same floats as n single calls), built once per n."""
        if n not in self._mapped:
            self._mapped[n] = (self.ocp.slack_fn.map(n), self.ocp.cost_fn.map(n))
        return self._mapped[n]

    def _shift(self, plan: _Plan) -> _Plan:
        """Advance a stored plan by one step: drop its first stage and repeat the last control."""
        last = step_numpy(plan.states[-1], plan.controls[-1], self.config.dt_s, self.config.robot.model)
        states = np.vstack([plan.states[1:], last])
        controls = np.vstack([plan.controls[1:], plan.controls[-1:]])
        return _Plan(states, controls, plan.age + 1)

    # -- fallback ------------------------------------------------------------------------------
    def _fallback(self, state, status, solver_status, elapsed, iters, max_slack) -> PlanResult:
        """Replay the previous plan (shifted) while it is young enough, else brake; never raises."""
        cfg = self.config
        kind, wanted = ("brake", []) if self._plan is None else ("previous_plan", list(self._plan.controls))
        controls, states = [], [state]
        for k in range(cfg.horizon_steps):
            x = states[-1]
            u = clip_control(x, wanted[k], cfg.dt_s, cfg.robot) if k < len(wanted) else \
                brake_control(x, cfg.dt_s, cfg.robot)
            controls.append(u)
            states.append(step_numpy(x, u, cfg.dt_s, cfg.robot.model))
        controls = np.array(controls)
        return PlanResult(controls[0].copy(), np.array(states), controls, status, solver_status, elapsed,
                          iters, float(max_slack), kind)
