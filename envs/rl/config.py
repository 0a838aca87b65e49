"""The settings of a training run (`TrainConfig`, saved as config.json): the env it trains in (a scenario, or a
benchmark suite's cell), PPO's hyper-parameters (and, for constrained PPO, the cost terms and budget), the warm start
and the evaluation; `envs.rl.train` runs it."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from envs.config import DEFAULT_PREDICTOR, CrowdNavConfig, ObservationConfig, RewardWeights
from envs.rl.cost import COST_SOURCES
from envs.rl.setting import TRAIN_SEED_OFFSET, check_disjoint, check_seeds, suite_env_config

if TYPE_CHECKING:
    from envs.rl.mix import Mix

WARM_STARTS = ("none", "bc", "dagger")
LAGRANGE_FIELDS = ("cost_budget", "lambda_lr", "lambda_init")  # the multiplier's settings (constrained PPO only)
# The env settings of a run without a suite (None in TrainConfig: not given). With a suite they come from its cell,
# and giving any of them is an error.
SCENARIO_DEFAULTS: dict[str, Any] = {"scenario": "circle_crossing", "pedestrians": 5, "invisible": True,
                                     "time_limit_s": 40.0}
# --quick: a smoke run of the whole pipeline (warm start, PPO, evaluation, checkpoints), not a usable agent.
QUICK: dict[str, Any] = {"total_steps": 4096, "n_steps": 256, "eval_every_steps": 2048, "eval_episodes": 5,
                         "checkpoint_every_steps": 2048, "demo_episodes": 5, "bc_epochs": 5, "dagger_rounds": 1,
                         "dagger_episodes": 3}


@dataclass(frozen=True)
class TrainConfig:
    """Everything a run depends on (saved as config.json; defaults run). Steps are agent steps (decisions), each
    `decision_every_steps` env steps."""

    suite: str = ""                   # train in a simulated cell of this benchmark suite ("": the four below)
    cell: str = ""                    # the suite's cell ("": its only cell)
    mix: str = ""                     # train in a mix of suite cells (envs.rl.mix.MIXES), instead of suite/scenario
    scenario: str | None = None       # None: circle_crossing (without a suite)
    pedestrians: int | None = None    # None: 5
    invisible: bool | None = None     # pedestrians do not see the robot (CrowdNav's invisible setting); None: True
    time_limit_s: float | None = None  # s; None: 40
    decision_every_steps: int = 1     # env steps per agent decision; the action is held in between
    max_pedestrians: int = 20         # P rows in the observation
    groups: bool = True               # the extractor pools rows by group id
    predictions: bool = False         # predicted futures in the observation and the extractor
    prediction_source: str = "predictor"  # "predictor" (the one named below) or "oracle" (the true future)
    predictor: str = DEFAULT_PREDICTOR  # the observation's predictor (name, checkpoint or module:factory)
    calibration: bool = False         # the predictions' running conformal calibration in the observation and extractor
    calibration_alpha: float = 0.1    # its miscoverage level: the (1 - alpha) quantile of the errors, in (0, 1)
    wall_rays: int = 0                # range rays to the walls in the observation (0: none)
    rewards: tuple[tuple[str, float], ...] = ()  # RewardWeights overrides, e.g. (("collision", -20.0),)
    total_steps: int = 1_000_000
    seed: int = 0
    envs: int = 8                     # parallel envs in the rollout
    workers: int = 1                  # 1: all envs in this process; = envs: one subprocess per env (SB3)
    n_steps: int = 256                # rollout length per env
    batch_size: int = 256
    n_epochs: int = 10
    learning_rate: float = 3e-4
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.0
    target_kl: float | None = None   # stop an update's epochs once the approximate KL passes 1.5x this
    log_std_init: float = -0.5
    warm_start: str = "none"          # "bc": behaviour cloning of demo_policy before PPO; "dagger": then DAgger
    demo_policy: str = "mpc-gpgraph"
    # the demonstrating policy's MPC settings on top of the suite's (its planner, or a NAME+shield's shield), as
    # `crowdnav benchmark --mpc` items, e.g. ("shield_horizon_s=0.5",)
    demo_mpc: tuple[str, ...] = ()
    # start from this agent's policy (a packaged agent's name or an SB3 .zip); "": new. With a warm start, the warm
    # start's cloning continues from it (which may re-fit it to another decision period: distillation)
    init_from: str = ""
    demo_episodes: int = 60
    demo_seed: int = 200_000
    demo_successes_only: bool = False  # keep only the demonstrations the expert succeeded in (not DAgger's labels)
    bc_epochs: int = 30
    bc_rotations: bool = False        # clone on scenes turned at random (holonomic robot, no walls; check_rotatable)
    bc_detach_critic: bool = False    # cloning's return regression trains the critic's own layers only
    dagger_rounds: int = 3            # DAgger: roll the learner out, expert labels, clone again on the aggregate
    dagger_episodes: int = 30         # learner episodes per DAgger round
    dagger_epochs: int | None = None  # cloning passes over the aggregate after each DAgger round (None: bc_epochs)
    eval_every_steps: int = 100_000
    eval_episodes: int = 30
    eval_seed: int = 100_000
    checkpoint_every_steps: int = 50_000
    threads: int = 1                  # torch threads in the learner process
    # constrained PPO (envs.rl.lagrangian): cost terms and weights (envs.rl.cost), e.g. (("collision", 1.0),); (): PPO
    constraint: tuple[tuple[str, float], ...] = ()
    cost_budget: float | None = None  # mean episode cost allowed (cost units per episode); needed with constraint
    lambda_lr: float = 0.05           # multiplier step per rollout per cost unit of excess (J_c - budget)
    lambda_init: float = 0.0          # the multiplier at step 0 (reward units per cost unit)
    # the episode cost the multiplier is stepped on: "rollout", the exploring policy's episodes after each rollout;
    # "evaluation", the deterministic policy's evaluation episodes after each evaluation (the collision term only)
    cost_source: str = "rollout"

    def __post_init__(self) -> None:
        self._resolve_env_fields()
        ints = ("decision_every_steps", "max_pedestrians", "envs", "workers", "n_steps", "batch_size",
                "n_epochs", "demo_episodes", "bc_epochs", "dagger_rounds", "dagger_episodes", "eval_every_steps",
                "eval_episodes", "checkpoint_every_steps", "threads")
        for name in ints + (("dagger_epochs",) if self.dagger_epochs is not None else ()):  # unset: bc_epochs
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {getattr(self, name)!r}")
        if self.warm_start not in WARM_STARTS:
            raise ValueError(f"unknown warm_start {self.warm_start!r}; valid: {', '.join(WARM_STARTS)}")
        self._check_total_steps()
        if self.init_from:
            self.init_path()  # names an agent that exists
        if self.demo_mpc:
            if self.warm_start == "none":
                raise ValueError("demo_mpc sets the demonstrating policy's MPC; it needs warm_start bc or dagger")
            self.demo_mpc_overrides()
        if self.workers not in (1, self.envs):
            raise ValueError(f"workers must be 1 (all envs in this process) or equal to envs ({self.envs}: one "
                             f"subprocess per env, SB3's SubprocVecEnv), got {self.workers}")
        if not isinstance(self.wall_rays, int) or self.wall_rays < 0:
            raise ValueError(f"wall_rays must be an integer >= 0, got {self.wall_rays!r}")
        if self.target_kl is not None and not self.target_kl > 0:
            raise ValueError(f"target_kl must be > 0 (or unset), got {self.target_kl}")
        if not (0 < self.gamma <= 1 and 0 < self.gae_lambda <= 1 and self.learning_rate > 0 and self.clip_range > 0):
            raise ValueError("gamma and gae_lambda must be in (0, 1], learning_rate and clip_range > 0")
        self._check_constraint()
        self.env_config().sim_config()  # validates the scenario, crowd size (against the group sizes), rewards
        seeds = self.seed_ranges()
        for what, r in seeds.items():
            check_seeds(what, r)
        check_disjoint(seeds)

    def _check_total_steps(self) -> None:
        """total_steps: an integer >= 1, or 0 (no PPO) when the policy comes from a warm start or an agent."""
        n = self.total_steps
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            raise ValueError(f"total_steps must be an integer >= 0, got {n!r}")
        if n == 0 and self.warm_start == "none" and not self.init_from:
            raise ValueError("total_steps 0 (no PPO) needs a policy to keep: a warm start or init_from")

    def demo_mpc_overrides(self) -> dict[str, Any]:
        """{MPCConfig field: value} of `demo_mpc` (`envs.cli_options.mpc_overrides`); ValueError naming the valid
        fields."""
        from envs.cli_options import mpc_overrides

        if isinstance(self.demo_mpc, str) or not all(isinstance(x, str) for x in self.demo_mpc):
            raise ValueError(f"demo_mpc must be a list of FIELD=VALUE strings, got {self.demo_mpc!r}")
        try:
            return mpc_overrides(list(self.demo_mpc))
        except ValueError as exc:
            raise ValueError(f"demo_mpc: {exc}".replace("--mpc ", "")) from None

    def _resolve_env_fields(self) -> None:
        """Fill the env settings left None (no suite) with `SCENARIO_DEFAULTS`; with a suite, refuse any given."""
        if not isinstance(self.suite, str) or not isinstance(self.cell, str) or not isinstance(self.mix, str):
            raise ValueError("suite, cell and mix must be names (strings)")
        if self.cell and not self.suite:
            raise ValueError(f"cell {self.cell!r} needs its suite (--suite)")
        if self.mix and self.suite:
            raise ValueError(f"mix {self.mix} names its own cells; drop --suite {self.suite}")
        if self.suite or self.mix:
            where = f"suite {self.suite}: its cell" if self.suite else f"mix {self.mix}: its cells"
            given = ["--" + k.replace("_", "-") for k in SCENARIO_DEFAULTS if getattr(self, k) is not None]
            if given:
                raise ValueError(f"{where} set the env, so {', '.join(given)} would be ignored; drop them")
            return
        for key, value in SCENARIO_DEFAULTS.items():
            if getattr(self, key) is None:
                object.__setattr__(self, key, value)
        if not isinstance(self.pedestrians, int) or self.pedestrians < 1:
            raise ValueError(f"pedestrians must be an integer >= 1, got {self.pedestrians!r}")

    def _check_constraint(self) -> None:
        """The constraint's terms and weights (`envs.rl.cost.check_constraint`), and its budget and multiplier
        settings: finite numbers, the budget and initial multiplier >= 0, the step > 0; without a constraint, none
        of the three may differ from its default. Numbers are kept as floats."""
        from envs.rl.cost import check_constraint

        check_constraint(self.constraint)
        defaults = {f.name: f.default for f in dataclasses.fields(self) if f.name in LAGRANGE_FIELDS}
        if self.cost_source not in COST_SOURCES:
            raise ValueError(f"unknown cost_source {self.cost_source!r}; valid: {', '.join(COST_SOURCES)}")
        if not self.constraint:
            given = [f"--{k.replace('_', '-')}" for k, v in defaults.items() if getattr(self, k) != v]
            given += ["--cost-source"] if self.cost_source != "rollout" else []
            if given:
                raise ValueError(f"{', '.join(given)} only apply to constrained PPO; add --constraint TERM=WEIGHT")
            return
        if self.cost_budget is None:
            raise ValueError("constrained PPO needs a cost budget (--cost-budget, mean cost per episode)")
        if self.cost_source == "evaluation" and [t for t, _ in self.constraint] != ["collision"]:
            raise ValueError("--cost-source evaluation measures collisions only: use --constraint collision=WEIGHT")
        for name in LAGRANGE_FIELDS:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
            object.__setattr__(self, name, float(value))
        if self.cost_budget < 0 or self.lambda_init < 0 or not self.lambda_lr > 0:
            raise ValueError(f"cost_budget and lambda_init must be >= 0 and lambda_lr > 0, got {self.cost_budget}, "
                             f"{self.lambda_init} and {self.lambda_lr}")

    def seed_ranges(self) -> dict[str, range]:
        """The reset seeds of every episode this run draws: training (the first reset of each env; later resets
        continue each env's random stream), evaluation, and demonstrations (BC and DAgger; none without a warm
        start)."""
        demos = 0 if self.warm_start == "none" else self.demo_episodes
        if self.warm_start == "dagger":
            demos += self.dagger_rounds * self.dagger_episodes
        first = TRAIN_SEED_OFFSET + self.seed
        return {"training seeds (10000000 + seed)": range(first, first + self.envs),
                "eval_seed": range(self.eval_seed, self.eval_seed + self.eval_episodes),
                "demo_seed": range(self.demo_seed, self.demo_seed + demos)}

    def init_path(self) -> Path:
        """The agent file `init_from` names: a path ending in .zip, else a packaged agent
        (`envs.policies.AGENTS_DIR`); ValueError naming the packaged agents when there is none."""
        from crowdsim.names import unknown_name
        from envs.policies import AGENTS_DIR

        if self.init_from.endswith(".zip"):
            path = Path(self.init_from)
            if not path.is_file():
                raise ValueError(f"init_from: no such agent file {path}")
            return path
        packaged = sorted(p.stem for p in AGENTS_DIR.glob("*.zip"))
        if self.init_from not in packaged:
            raise ValueError(unknown_name("agent", self.init_from, packaged, "packaged agents (or an SB3 .zip)"))
        return AGENTS_DIR / f"{self.init_from}.zip"

    def input_digests(self) -> dict[str, str]:
        """The sha256 of the files this run reads by path (a scenario file, the agent it starts from): kept beside
        config.json (inputs.json) and in every saved agent, and checked on --resume, so that a file edited since the
        run began cannot silently change what it trains on."""
        import hashlib

        from crowdsim.scenarios import scenario_digest

        out = {}
        digest = None if self.scenario is None else scenario_digest(self.scenario)
        if digest is not None:
            out["scenario_sha256"] = digest
        if self.init_from:
            out["init_from_sha256"] = hashlib.sha256(self.init_path().read_bytes()).hexdigest()
        return out

    def check_inputs(self, saved: dict[str, str]) -> None:
        """ValueError naming each input file whose sha256 differs from `saved` (a run's inputs.json)."""
        now = self.input_digests()
        changed = sorted(k for k in set(saved) | set(now) if saved.get(k) != now.get(k))
        if changed:
            what = {"scenario_sha256": f"the scenario file {self.scenario}",
                    "init_from_sha256": f"the agent {self.init_from}"}
            raise ValueError(f"{' and '.join(what.get(k, k) for k in changed)} changed since the run began; "
                             "restore it or start a new run")

    @property
    def env_cell(self) -> str:
        """The suite cell trained in ("" without a suite; the mix's name with one)."""
        return suite_env_config(self.suite, self.cell)[0] if self.suite else self.mix

    def reward_overrides(self) -> dict[str, float]:
        """This run's reward weights as `RewardWeights` fields; ValueError naming the valid terms."""
        names = {"progress": "progress_per_m", "success": "success", "collision": "collision",
                 "discomfort": "discomfort_per_s", "group_intrusion": "group_intrusion_per_s", "time": "time_per_s"}
        unknown = [k for k, _ in self.rewards if k not in names]
        if unknown:
            raise ValueError(f"unknown reward term(s) {unknown}; valid: {', '.join(names)}")
        return {names[k]: float(v) for k, v in self.rewards}

    def mixture(self) -> Mix | None:
        """The `envs.rl.mix.Mix` trained in (None without --mix), with this run's observation and reward weights."""
        if not self.mix:
            return None
        from envs.rl.mix import build_mix

        obs = tuple(self.observation_overrides().items())
        return build_mix(self.mix, obs, tuple(sorted(self.reward_overrides().items())))

    def observation_overrides(self) -> dict[str, Any]:
        """This run's `ObservationConfig` fields (a suite's or a mix's cells keep their other fields)."""
        return {"max_pedestrians": self.max_pedestrians, "predictions": self.predictions, "wall_rays": self.wall_rays,
                "prediction_source": self.prediction_source, "predictor": self.predictor,
                "prediction_calibration": self.calibration, "calibration_alpha": self.calibration_alpha}

    def env_config(self) -> CrowdNavConfig:
        """The env every training and evaluation episode runs in: the suite cell's (with this run's observation
        and reward weights), or the one the scenario fields describe. With a mix: its first cell's, whose
        observation layout and robot every cell shares (`mixture().config_for` gives each episode's)."""
        if self.mix:
            return self.mixture().base
        overrides = self.reward_overrides()
        if self.suite:
            _, cfg = suite_env_config(self.suite, self.cell)
            obs = replace(cfg.observation, **self.observation_overrides())
            return replace(cfg, observation=obs, rewards=replace(cfg.rewards, **overrides))
        weights = replace(RewardWeights(), **overrides)
        obs = ObservationConfig(**self.observation_overrides())
        return CrowdNavConfig(scenario=self.scenario, n_pedestrians=self.pedestrians,
                              robot_visible=not self.invisible, time_limit_s=self.time_limit_s, rewards=weights,
                              observation=obs)

    def to_json(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["rewards"] = {k: v for k, v in self.rewards}
        d["constraint"] = {k: v for k, v in self.constraint}
        return d

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> TrainConfig:
        """A config from JSON/TOML data; unknown keys are an error."""
        fields = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - fields)
        if unknown:
            raise ValueError(f"unknown setting(s) {unknown}; valid: {', '.join(sorted(fields))}")
        data = dict(data)
        for key in ("rewards", "constraint"):  # TOML tables / JSON objects of term = weight
            if key in data:
                data[key] = tuple((str(k), _number(key, k, v)) for k, v in dict(data[key]).items())
        if isinstance(data.get("demo_mpc"), list):  # a JSON / TOML list of FIELD=VALUE strings
            data["demo_mpc"] = tuple(data["demo_mpc"])
        return cls(**data)


def _number(table: str, key: str, value: Any) -> float:
    """A weight of a term table as a float; ValueError naming it when it is not a number."""
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        raise ValueError(f"{table}.{key} must be a number, got {value!r}")
    try:
        return float(value)
    except ValueError:
        raise ValueError(f"{table}.{key} must be a number, got {value!r}") from None


def term_weights(key: str, items: list[str]) -> dict[str, float]:
    """{term: weight} of the values of a repeatable --reward (key "rewards") or --constraint flag, each
    TERM=WEIGHT[,TERM=WEIGHT...]; ValueError on a malformed one (`TrainConfig` checks the names)."""
    flag, out = "--reward" if key == "rewards" else "--" + key, {}
    for item in (part for value in items for part in value.split(",")):
        name, sep, value = item.partition("=")
        try:
            if not sep:
                raise ValueError
            out[name.strip()] = float(value)
        except ValueError:
            raise ValueError(f"{flag} {item!r}: expected TERM=WEIGHT with a number") from None
    return out
