"""Policies for `CrowdNavEnv`: one constructor (`PolicyConfig` -> `make_policy`), a small registry, plug-ins.

Registry names:

    mpc-gpgraph   MPC + a GP-Graph predictor (default the shipped synthetic one): K samples, its own groups
    mpc-oracle    the same MPC fed the pedestrians' true future and true groups: the prediction upper bound (a
                  reference; it and mpc-oracle-paths alone read the privileged `view.future`)
    mpc-oracle-paths   the two halves between mpc-gpgraph and mpc-oracle, which separate trajectory error from
    mpc-oracle-groups  grouping error: true futures with the predictor's groups; the predictor's samples with the
                  true groups (where a crowd has no group labels, every pedestrian alone)
    mpc-cv        MPC + constant-velocity prediction, every pedestrian its own group
    mpc-none      MPC with pedestrians frozen where they stand (no prediction), no groups
    social-force  reactive social-force robot (every env step)
    random        uniform random actions (a baseline and a benchmark load)
    orca          ORCA driving the robot, every pedestrian an ORCA agent (`envs.policies.orca`; the CrowdNav papers'
                  baseline; needs the optional package pyrvo)
    ppo-crowdnav  the shipped PPO agent (`envs/policies/agents/ppo-crowdnav.zip`, trained with `envs.rl.train`: circle
                  crossing, 5 pedestrians who do not see the robot; RESULTS.md "RL baseline")
    ppo-crowdnav-classic  the shipped PPO agent for CrowdNav's classic setting (suite crowdnav-classic: 5 ORCA humans
                  who do not see the robot, holonomic robot; acts every 0.25 s; RESULTS.md "RL agents for CrowdNav's
                  settings"); other envs refuse it (robot model)
    ppo-crowdnav-20  the shipped PPO agent for CrowdNav++'s setting (suite crowdnav-plusplus: 20 ORCA humans who do
                  not see the robot, holonomic robot, 5 m sensor; acts every 0.25 s; same RESULTS section)
    ppo-crowdnav-20-distilled  the same network re-fitted by DAgger to `ppo-crowdnav-20+shield` deciding every env step
                  (0.05 s): the shield's corrections learnt, no shield at run time; acts every 0.05 s (RESULTS.md
                  "RL, the shield distilled into the agent"); crowdnav-plusplus only
    ppo-crowdnav-mix  a generalist (`crowdnav train --mix crowdnav-v1-train-dense`: crowdnav-v1's simulated cells and
                  two recorded crowds outside every test split, also overlaid as dense crowds; 16 wall rays, which
                  `crowdnav benchmark` gives it, and `crowdnav evaluate` with --wall-rays 16; acts every 0.2 s;
                  RESULTS.md "RL, a generalist")

Any of these but the MPC policies (whose planner routes and shields already) may be followed by `+route` (it heads
for the global route's subgoal through the walls, `envs.policies.routed`) and `+shield` (its decisions pass the MPC's
safety shield, on constant-velocity futures, before the env applies them, `envs.policies.shielded`), in that order:
`ppo-crowdnav-mix+route+shield`. Besides these, `PolicyConfig.name` may be `module:factory` (a user
policy, `envs.policies.plugins`) or `sb3:PATH.zip`
(a stable-baselines3 agent), and `PolicyConfig.predictor` a predictor name, checkpoint or `module:factory`.
Every policy reads a `PolicyView` and returns a `Decision` (`envs.view`): `act(view) -> Decision`; it never
calls back into the env. `act(policy, env)` below is the one loop step that asks the env for the view, applies
the decision's annotations and returns the env action. Planner policies re-plan every `replan_every_steps` env
steps from a history of 0.4 s-spaced positions that ends now and hold the planned control in between (the env
clips it to the accelerations reachable per env step).
"""

from __future__ import annotations

import inspect
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from crowdsim.names import did_you_mean
from envs.config import DEFAULT_PREDICTOR
from envs.env import CrowdNavEnv
from envs.factories import is_plugin, load_factory
from envs.policies.plugins import SB3_PREFIX, SB3Policy
from envs.policies.routed import RoutedPolicy
from envs.policies.shielded import ShieldedPolicy
from envs.policies.wrappers import ROUTE_SUFFIX, SHIELD_SUFFIX, split_wrappers
from envs.prediction import load_predictor_spec, predict
from envs.timing import PredictionTiming
from envs.view import Decision, PolicyView
from planner import (
    CROWD_MPC,
    MPCConfig,
    MPCPlanner,
    PedPrediction,
    PlanStats,
    empty_prediction,
    make_planner,
)

# The MPC as the env runs it (all MPC policies): `planner.CROWD_MPC` (its settings and how they were tuned:
# docs/decisions/planner-settings.md). Re-planned every env step (0.1 s): between 0.4 s ticks the predictor's history
# is interpolated to end now (`CrowdNavEnv.history_window`), so any interval works; why every step:
# docs/decisions/replanning.md.
ENV_MPC = CROWD_MPC
REPLAN_EVERY_STEPS = 1
# registry policies that take `PolicyConfig.predictor`
PREDICTOR_POLICIES = ("mpc-gpgraph", "mpc-oracle-paths", "mpc-oracle-groups")
SCENE_TEMPLATE = "{scene}"  # in a predictor name: filled in per benchmark cell (`PolicyConfig.for_cell`)


@dataclass(frozen=True)
class PolicyConfig:
    """Everything that makes a policy; the only way one is built (`make_policy`) and recorded with results.

    name: a registry name (`POLICIES`), `module:factory` or `sb3:PATH.zip` / `sb3:ALGO:PATH.zip`.
    mpc: the planner settings of the MPC policies (the robot's limits are replaced by the env's).
    replan_every_steps: env steps between re-plans (planner policies).
    predictor: for mpc-gpgraph (and plug-ins that want one): a predictor name, checkpoint path or
        `module:factory`; None is the shipped default. Setting it for a policy that ignores it is an error.
    n_samples: predicted samples per plan (K).
    threads: torch threads in the process (predictor, SB3).
    deterministic: SB3 agents act deterministically.
    """

    name: str = "mpc-gpgraph"
    mpc: MPCConfig = field(default_factory=lambda: ENV_MPC)
    replan_every_steps: int = REPLAN_EVERY_STEPS
    predictor: str | None = None
    n_samples: int = 20
    threads: int = 1
    deterministic: bool = True

    def __post_init__(self) -> None:
        base, _ = split_wrappers(self.name)
        plug = is_plugin(base) or base.startswith(SB3_PREFIX)
        if not plug and base not in POLICIES:
            raise ValueError(f"unknown policy {self.name!r};{did_you_mean(base, POLICIES)} valid names: "
                             f"{', '.join(POLICIES)}, "
                             f"module:factory or sb3:PATH.zip, each optionally followed by {ROUTE_SUFFIX} and/or "
                             f"{SHIELD_SUFFIX}")
        if self.predictor is not None and not (base in PREDICTOR_POLICIES or is_plugin(base)):
            raise ValueError(f"policy {self.name!r} takes no predictor (only {', '.join(PREDICTOR_POLICIES)} "
                             "and module:factory policies do)")
        for key in ("replan_every_steps", "n_samples", "threads"):
            if not isinstance(getattr(self, key), int) or getattr(self, key) < 1:
                raise ValueError(f"PolicyConfig.{key} must be an integer >= 1, got {getattr(self, key)!r}")

    def for_cell(self, scene: str, cell_predictor: str | None) -> PolicyConfig:
        """This config as run in one benchmark cell: `{scene}` in the predictor becomes the cell's scene, and
        a registry predictor policy without a predictor takes the cell's own (`cell_predictor`, if any)."""
        if self.predictor is not None and SCENE_TEMPLATE in self.predictor:
            return replace(self, predictor=self.predictor.replace(SCENE_TEMPLATE, scene))
        if self.predictor is None and cell_predictor is not None and self.name in PREDICTOR_POLICIES:
            return replace(self, predictor=cell_predictor)
        return self

    def predictor_used(self) -> str | None:
        """The predictor this policy runs: the one given, else the shipped `DEFAULT_PREDICTOR` for the predictor
        policies (`PREDICTOR_POLICIES`); None for a policy that runs none (a plug-in given none chooses its own)."""
        if self.predictor is not None:
            return self.predictor
        return DEFAULT_PREDICTOR if split_wrappers(self.name)[0] in PREDICTOR_POLICIES else None

    def to_json(self) -> dict[str, Any]:
        """The whole config as JSON-ready data (goes into every results file)."""
        return _json_safe(asdict(self))


def _json_safe(obj: Any) -> Any:
    """obj with tuples as lists and non-finite floats as the strings "inf", "-inf", "nan" (strict JSON)."""
    if isinstance(obj, dict):
        return {str(k): _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, float) and not np.isfinite(obj):
        return str(obj)
    return obj if obj is None or isinstance(obj, bool | int | float | str) else str(obj)


class Policy(Protocol):
    """What the episode loop needs of a policy. Optional: `stats` (a `planner.PlanStats`), and `reads_history`
    (False: the policy reads no `view.history`, which is then None and not computed; an int k: only the window's
    newest k rows; default True, the whole window), `reads_future` (privileged `view.future`; `future_s`, s: at least
    this much of it, where longer than the predictor's horizon) and `reads_track`
    (True: `view.track`, the pedestrians' longer past, for a predictor whose group rule reads it; default False)."""

    name: str

    def reset(self, seed: int | None = None) -> None:
        """Start an episode (after env.reset)."""

    def act(self, view: PolicyView) -> Decision:
        """The decision for the current step, from the view alone."""


def decide(policy: Policy, env: CrowdNavEnv) -> Decision:
    """One step of the episode loop: the policy's decision on the env's view, its annotations attached to the
    frames drawn from now on. `env.step_decision(decision)` applies it (a control as it is)."""
    decision = policy.act(env.view(history=getattr(policy, "reads_history", True),
                                   future=getattr(policy, "reads_future", False),
                                   future_s=getattr(policy, "future_s", 0.0),
                                   track=getattr(policy, "reads_track", False)))
    if decision.annotated:
        env.annotate(decision.plan, decision.predictions, decision.predicted_group_id, decision.options)
    return decision


def act(policy: Policy, env: CrowdNavEnv) -> np.ndarray:
    """`decide`, as the env action (2,) float32 it asks for (for a Gym loop, or imitation labels; a control is
    mapped to its action)."""
    return env.action_for(decide(policy, env))


class PlannerPolicy:
    """A planner re-planning every `replan_every_steps` env steps; `predict(view)` builds the `PedPrediction`."""

    def __init__(self, name: str, planner: Any, predict: Callable[[PolicyView], PedPrediction],
                 replan_every_steps: int = REPLAN_EVERY_STEPS) -> None:
        if replan_every_steps < 1:
            raise ValueError(f"replan_every_steps must be >= 1, got {replan_every_steps}")
        self.name, self.planner, self._predict = name, planner, predict
        self.replan_every_steps = replan_every_steps
        self._control: np.ndarray | None = None
        self._age = 0

    @property
    def stats(self) -> PlanStats:
        return self.planner.stats

    def reset(self, seed: int | None = None) -> None:
        self.planner.reset()
        self._control = None

    def act(self, view: PolicyView) -> Decision:
        if self._control is not None and self._age < self.replan_every_steps:
            self._age += 1
            return Decision(control=self._control)  # hold the plan; the frames keep its annotations
        self._age = 1
        prediction = self._predict(view)
        result = self.planner.plan(view.robot_state, view.goal, prediction, view.walls)
        self._control = result.control
        samples = prediction.positions if prediction.n_peds else None
        options = np.array([o[:, :2] for o in result.options[1:]]) if len(result.options) > 1 else None
        return Decision(control=self._control, plan=result.states[:, :2], predictions=samples,
                        predicted_group_id=prediction.group_ids if prediction.n_peds else None, options=options)


class GPGraphPolicy(PlannerPolicy):
    """MPC + a predictor's samples and group assignment (GP-Graph by default)."""

    def __init__(self, config: MPCConfig, predictor: str | None = DEFAULT_PREDICTOR, n_samples: int = 20,
                 threads: int = 1, replan_every_steps: int = REPLAN_EVERY_STEPS,
                 env_timing: PredictionTiming | None = None) -> None:
        self.predictor = load_predictor_spec(predictor, threads, env_timing)
        self.reads_track = bool(getattr(self.predictor, "reads_track", False))  # its group rule reads the track
        self.timing = PredictionTiming.of(self.predictor)
        self.n_samples = n_samples
        self.rng = np.random.default_rng(0)
        super().__init__("mpc-gpgraph", MPCPlanner(config), self._gpgraph, replan_every_steps)

    def reset(self, seed: int | None = None) -> None:
        super().reset(seed)
        self.rng = np.random.default_rng(seed)

    def _gpgraph(self, view: PolicyView) -> PedPrediction:
        p, t = view.pedestrians, view.timing
        if len(p.pos) == 0:
            return empty_prediction(t.pred_len, t.step_s)
        samples, group_id = predict(self.predictor, view.history, self.n_samples, self.rng, t.pred_len, view.track)
        return PedPrediction(samples, p.radius, group_id, np.ones(len(p.pos), bool), current=p.pos,
                             history=view.history, step_s=t.step_s)


def oracle_prediction(view: PolicyView) -> PedPrediction:
    """The pedestrians' true future (`view.future`, privileged) as a one-sample prediction, with their true groups.
    A pedestrian who leaves within the horizon is held where it was last (the planner takes no partial tracks)."""
    p, t = view.pedestrians, view.timing
    if view.future is None:
        raise ValueError("the oracle needs the view's future (env.view(future=True), as envs.policies.act asks for "
                         "policies with reads_future = True)")
    if len(p.pos) == 0:
        return empty_prediction(t.pred_len, t.step_s)
    future = np.concatenate([p.pos[None], view.future])  # (1 + T, N, 2): now, then the future
    for k in range(1, len(future)):  # hold the last known position where a track has ended
        gone = np.isnan(future[k, :, 0])
        future[k, gone] = future[k - 1, gone]
    return PedPrediction(future[None, 1:], p.radius, p.group_id, np.ones(len(p.pos), bool), current=p.pos,
                         history=view.history, step_s=t.step_s)


def oracle_future_s(config: MPCConfig) -> float:
    """How far ahead (s) an oracle policy reads the true future: the MPC's whole horizon, however long (--mpc), and
    the foresight search's view where that is longer."""
    horizon = config.horizon_steps * config.dt_s
    return horizon if config.foresight is None else max(horizon, config.foresight.horizon_s)


class OraclePolicy(PlannerPolicy):
    """`mpc-oracle`: the MPC of mpc-gpgraph fed the true future instead of a prediction (a reference, not a deployable
    policy: it reads `view.future`, which the env computes for it alone; its plan time is reported, not budgeted)."""

    reads_future = True

    def __init__(self, config: MPCConfig, replan_every_steps: int = REPLAN_EVERY_STEPS) -> None:
        super().__init__("mpc-oracle", MPCPlanner(config), oracle_prediction, replan_every_steps)
        self.future_s = oracle_future_s(config)


class HalfOraclePolicy(GPGraphPolicy):
    """`mpc-oracle-paths` (half "paths": the true future as one sample, with the predictor's groups) and
    `mpc-oracle-groups` (half "groups": the predictor's samples, with the true groups): mpc-gpgraph with one of its two
    outputs replaced by the truth, so that the gap to mpc-oracle splits into trajectory and grouping error."""

    HALVES = ("paths", "groups")

    def __init__(self, half: str, config: MPCConfig, predictor: str | None = DEFAULT_PREDICTOR, n_samples: int = 20,
                 threads: int = 1, replan_every_steps: int = REPLAN_EVERY_STEPS,
                 env_timing: PredictionTiming | None = None) -> None:
        if half not in self.HALVES:
            raise ValueError(f"unknown half {half!r}; valid: {', '.join(self.HALVES)}")
        super().__init__(config, predictor, n_samples, threads, replan_every_steps, env_timing)
        self.half, self.name, self.reads_future = half, f"mpc-oracle-{half}", half == "paths"
        self.future_s = oracle_future_s(config) if self.reads_future else 0.0
        self._predict = self._half_truth

    def _half_truth(self, view: PolicyView) -> PedPrediction:
        predicted = self._gpgraph(view)
        if not predicted.n_peds:
            return predicted
        if self.half == "groups":
            return replace(predicted, group_ids=np.asarray(view.pedestrians.group_id))
        return replace(oracle_prediction(view), group_ids=predicted.group_ids)


def singleton_prediction(view: PolicyView) -> PedPrediction:
    """The observed history as a (placeholder) prediction with every pedestrian its own group; the
    baseline planners replace the positions (constant velocity, frozen)."""
    p, t = view.pedestrians, view.timing
    if len(p.pos) == 0:
        return empty_prediction(t.pred_len, t.step_s)
    n = len(p.pos)
    return PedPrediction(np.repeat(p.pos[None, None], t.pred_len, axis=1), p.radius, np.arange(n),
                         np.ones(n, bool), current=p.pos, history=view.history, step_s=t.step_s)


class RandomPolicy:
    """Uniform random actions from its own Generator."""

    name = "random"
    reads_history = False

    def __init__(self) -> None:
        self.stats = PlanStats()
        self.rng = np.random.default_rng(0)

    def reset(self, seed: int | None = None) -> None:
        self.rng = np.random.default_rng(seed)

    def act(self, view: PolicyView) -> Decision:
        return Decision(action=self.rng.uniform(-1.0, 1.0, 2).astype(np.float32))


Factory = Callable[[PolicyConfig, MPCConfig, CrowdNavEnv], Policy]
AGENTS_DIR = Path(__file__).parent / "agents"
# the packaged SB3 agents (AGENTS_DIR/NAME.zip), registry policies acting on the observation
PACKAGED_AGENTS = ("ppo-crowdnav", "ppo-crowdnav-classic", "ppo-crowdnav-20", "ppo-crowdnav-20-distilled",
                   "ppo-crowdnav-mix")


def _planner(name: str, every: int | None = None) -> Factory:
    """A planner of `planner.PLANNERS` (the same name) re-planning on singleton predictions."""
    return lambda cfg, mpc, env: PlannerPolicy(name, make_planner(name, mpc), singleton_prediction,
                                               every or cfg.replan_every_steps)


def _agent(name: str) -> Factory:
    """A packaged SB3 agent (envs/policies/agents/NAME.zip), loaded like `sb3:PATH.zip` and renamed."""
    def build(cfg: PolicyConfig, mpc: MPCConfig, env: CrowdNavEnv) -> Policy:
        path = AGENTS_DIR / f"{name}.zip"
        if not path.is_file():
            raise ValueError(f"policy {name!r}: its packaged agent {path} is missing")
        policy = SB3Policy(f"{SB3_PREFIX}{path}", env, cfg.deterministic, cfg.threads)
        policy.name = name
        return policy
    return build


POLICIES: dict[str, Factory] = {
    "mpc-gpgraph": lambda cfg, mpc, env: GPGraphPolicy(mpc, cfg.predictor, cfg.n_samples, cfg.threads,
                                                       cfg.replan_every_steps, env.timing),
    "mpc-oracle": lambda cfg, mpc, env: OraclePolicy(mpc, cfg.replan_every_steps),
    "mpc-oracle-paths": lambda cfg, mpc, env: HalfOraclePolicy("paths", mpc, cfg.predictor, cfg.n_samples, cfg.threads,
                                                               cfg.replan_every_steps, env.timing),
    "mpc-oracle-groups": lambda cfg, mpc, env: HalfOraclePolicy("groups", mpc, cfg.predictor, cfg.n_samples,
                                                                cfg.threads, cfg.replan_every_steps, env.timing),
    "mpc-cv": _planner("mpc-cv"),
    "mpc-none": _planner("mpc-none"),
    "social-force": _planner("social-force", every=1),
    "random": lambda cfg, mpc, env: RandomPolicy(),
    "orca": lambda cfg, mpc, env: _orca_policy(env),
    **{name: _agent(name) for name in PACKAGED_AGENTS},
}


def _orca_policy(env: CrowdNavEnv) -> Policy:
    from envs.policies.orca import OrcaPolicy

    return OrcaPolicy(env.config.orca.params)


def make_policy(spec: str | PolicyConfig, env: CrowdNavEnv) -> Policy:
    """The policy a `PolicyConfig` (or a bare name: its defaults) describes, for this env (its robot limits).
    Unknown names raise ValueError listing the valid ones."""
    cfg = spec if isinstance(spec, PolicyConfig) else PolicyConfig(name=spec)
    if cfg.predictor is not None and SCENE_TEMPLATE in cfg.predictor:
        raise ValueError(f"predictor {cfg.predictor!r}: {SCENE_TEMPLATE} is filled in per cell by crowdnav "
                         "benchmark only; name one predictor here")
    env = env.unwrapped if hasattr(env, "unwrapped") else env
    base, wrappers = split_wrappers(cfg.name)
    if wrappers:
        policy, mpc = make_policy(replace(cfg, name=base), env), replace(cfg.mpc, robot=env.config.robot)
        for suffix in wrappers:
            policy = RoutedPolicy(policy, mpc, env) if suffix == ROUTE_SUFFIX else ShieldedPolicy(policy, mpc)
        return policy
    if cfg.name.startswith(SB3_PREFIX):
        return SB3Policy(cfg.name, env, cfg.deterministic, cfg.threads)
    if is_plugin(cfg.name):
        return _current(load_factory(cfg.name)(cfg, env), cfg.name, env)
    return POLICIES[cfg.name](cfg, replace(cfg.mpc, robot=env.config.robot), env)


class LegacyPolicy:
    """A plug-in written for the protocol before `act(view)`: `reset(env, seed)` and `act(obs, env) -> action`.
    Still runs (it is handed the env it was built for), with a DeprecationWarning once; migrate by reading
    `view.obs` (or the typed fields) in `act(view)` and returning `Decision(action=...)` or `Decision(control=...)`."""

    reads_history = False  # it reads the observation (and, as before, the env it holds)

    def __init__(self, policy: Any, env: CrowdNavEnv) -> None:
        self.policy, self.env, self.name = policy, env, getattr(policy, "name", type(policy).__name__)

    @property
    def stats(self) -> PlanStats | None:
        return getattr(self.policy, "stats", None)

    def reset(self, seed: int | None = None) -> None:
        self.policy.reset(self.env, seed)

    def act(self, view: PolicyView) -> Decision:
        return Decision(action=np.asarray(self.policy.act(view.obs, self.env), np.float32).reshape(2))


def _current(policy: Any, spec: str, env: CrowdNavEnv) -> Any:
    """A plug-in policy as it is, or wrapped in `LegacyPolicy` when its `act` still takes (obs, env)."""
    if len(inspect.signature(policy.act).parameters) != 2:
        return policy
    warnings.warn(f"plug-in {spec!r} uses the old protocol act(obs, env); it runs through LegacyPolicy. Migrate to "
                  "act(view) -> Decision (README, 'Your own policy')", DeprecationWarning, stacklevel=3)
    return LegacyPolicy(policy, env)
