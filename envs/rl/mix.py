"""Training in many cells at once (a generalist agent): a mix of benchmark cells, each episode in one of them.

- `MIXES`: the named mixes, a small explicit registry. A mix lists (suite, cell, weight) entries; cell "*" means
  every simulated cell of the suite. `crowdnav-v1-train` is crowdnav-v1's 20 simulated cells (1 each) and
  crowdnav-tune's two recorded crowds, crowds_zara03 and uni_examples (5 each: a third of the episodes replay
  real people). Those two recordings lie outside every ETH/UCY test split; no test recording is ever trained on
  (`check_recordings`). `crowdnav-v1-train-dense` adds the same recordings overlaid (`ReplayConfig.overlay`: 5 and
  10 time-shifted copies superimposed), as dense as the univ test scene.
- `Mix`: the cells' env configs, with one observation layout and reward weights for all (a run's settings), and the
  cycle that maps an episode seed to its cell: seed s plays cell `cycle[s % len(cycle)]` with reset seed s. The
  cycle holds each cell once per unit of weight, so any run of len(cycle) consecutive seeds (demonstrations, DAgger
  roll-outs, evaluations) plays each cell in proportion to its weight.
- `MixEnv`: a Gymnasium env over a `Mix`. `reset(seed=s)` plays seed s; a reset without a seed draws the next
  episode seed from the env's own stream (seeded by the last explicit seed), above `MIX_SEED_LOW`, far from every
  suite's, evaluation and demonstration seed. One `CrowdNavEnv` per cell is built on first use and kept.

Every cell of a mix must share the robot model, the time step and the observation space (checked at build time),
so that one agent acts in all of them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np

from envs.config import CrowdNavConfig

# (suite, cell, weight, overlay); cell "*": every simulated cell of the suite; overlay K > 1 (replay cells only):
# the recording with K time-shifted copies superimposed (`ReplayConfig.overlay`), a crowd K times as dense.
MIXES: dict[str, tuple[tuple[str, str, int, int], ...]] = {
    "crowdnav-v1-train": (("crowdnav-v1", "*", 1, 1), ("crowdnav-tune", "tune-zara03", 5, 1),
                          ("crowdnav-tune", "tune-uni-examples", 5, 1)),
    # as dense as the univ test scene (median 34-49 people a frame) where crowdnav-v1-train's recordings have 3-6
    "crowdnav-v1-train-dense": (("crowdnav-v1", "*", 1, 1), ("crowdnav-tune", "tune-zara03", 3, 1),
                                ("crowdnav-tune", "tune-uni-examples", 2, 1), ("crowdnav-tune", "tune-zara03", 3, 5),
                                ("crowdnav-tune", "tune-uni-examples", 5, 10)),
}
# The suites whose recordings are for choosing settings, not for reporting: their recordings may be trained on (at
# seeds they do not report). Every other suite's recordings (the ETH/UCY test files) never are.
TUNING_SUITES = ("crowdnav-tune",)
MIX_SEED_LOW = 2**30  # seedless resets draw episode seeds in [2^30, 2^32): above every other seed range of a run
MIX_SEED_HIGH = 2**32 - 1


@dataclass(frozen=True)
class Mix:
    """name; cells ((label "suite/cell", env config), ...); cycle: indices into cells, one per weight unit."""

    name: str
    cells: tuple[tuple[str, CrowdNavConfig], ...]
    cycle: tuple[int, ...]
    mpc_suite: str  # the suite whose planner defaults the expert MPC runs (the mix's first suite)

    def cell_of(self, seed: int) -> tuple[str, CrowdNavConfig]:
        """(label, env config) of the cell that episode `seed` plays."""
        return self.cells[self.cycle[int(seed) % len(self.cycle)]]

    def config_for(self, seed: int) -> CrowdNavConfig:
        return self.cell_of(seed)[1]

    @property
    def base(self) -> CrowdNavConfig:
        """The first cell's config: its observation layout and robot are every cell's (`check_compatible`)."""
        return self.cells[0][1]


@lru_cache(maxsize=1)
def reported_recordings() -> frozenset[str]:
    """The resolved paths of every recording a non-tuning shipped suite replays (the ETH/UCY test files)."""
    from importlib import resources

    from envs.evaluation.suite import DEFAULT_DATA, load_suite

    names = [p.name[:-5] for p in resources.files("envs.evaluation.suites").iterdir() if p.name.endswith(".json")]
    out = set()
    for name in names:
        if name in TUNING_SUITES:
            continue
        for cell in load_suite(name).cells:
            if cell.is_real:
                out.update(str(p.resolve()) for p in cell.files(DEFAULT_DATA))
    return frozenset(out)


def check_recordings(label: str, config: CrowdNavConfig) -> None:
    """ValueError when a replay cell replays a recording some suite reports (a test file)."""
    if config.replay is not None and str(config.replay.path.resolve()) in reported_recordings():
        raise ValueError(f"mix cell {label} replays {config.replay.path}, which a benchmark suite reports; training "
                         "never uses the reported recordings")


def check_compatible(cells: tuple[tuple[str, CrowdNavConfig], ...]) -> None:
    """ValueError unless every cell shares the first one's robot, time step and observation space."""
    from envs.observation import signature

    first_label, first = cells[0]
    for label, cfg in cells[1:]:
        for what, a, b in (("robot", first.robot, cfg.robot), ("dt_s", first.dt_s, cfg.dt_s),
                           ("observation", signature(first), signature(cfg))):
            if a != b:
                raise ValueError(f"mix cells {first_label} and {label} differ in {what} ({a} vs {b}); one agent "
                                 "cannot act in both")


def _entries(name: str) -> list[tuple[str, str, int, int]]:
    if name not in MIXES:
        raise ValueError(f"unknown mix {name!r}; valid: {', '.join(MIXES)}")
    from envs.evaluation.suite import load_suite

    out = []
    for suite, cell, weight, overlay in MIXES[name]:
        s = load_suite(suite)
        names = [c.name for c in s.cells if not c.is_real] if cell == "*" else [s.cell(cell).name]
        out.extend((suite, n, weight, overlay) for n in names)
    return out


def _cell_config(suite: str, cell: str, overlay: int) -> CrowdNavConfig:
    """The env config of a mix entry: the suite cell's, its recording overlaid `overlay` times."""
    from envs.evaluation.suite import load_suite

    c = load_suite(suite).cell(cell)
    cfg = c.env_config(c.seeds[0])
    if overlay == 1:
        return cfg
    if cfg.replay is None:
        raise ValueError(f"mix cell {suite}/{cell}: overlay {overlay} needs a replay cell")
    return replace(cfg, replay=replace(cfg.replay, overlay=overlay, name=f"{cfg.replay.name}-x{overlay}"))


@lru_cache(maxsize=8)
def build_mix(name: str, observation: tuple[tuple[str, Any], ...] = (),
              rewards: tuple[tuple[str, float], ...] = ()) -> Mix:
    """The mix `name` with this run's overrides of every cell's observation ((field of `ObservationConfig`, value),
    ...) and reward weights ((field of `RewardWeights`, value), ...). ValueError for an unknown name, a reported
    recording or cells that one agent cannot share."""
    entries = _entries(name)
    cells, slots = [], []
    for i, (suite, cell, weight, overlay) in enumerate(entries):
        cfg = _cell_config(suite, cell, overlay)
        cfg = replace(cfg, observation=replace(cfg.observation, **dict(observation)),
                      rewards=replace(cfg.rewards, **dict(rewards)))
        label = f"{suite}/{cell}" + (f"-x{overlay}" if overlay > 1 else "")
        check_recordings(label, cfg)
        cells.append((label, cfg))
        slots.extend(((j + 0.5) / weight, i) for j in range(weight))  # a cell's units spread over the cycle
    check_compatible(tuple(cells))
    return Mix(name, tuple(cells), tuple(i for _, i in sorted(slots)), entries[0][0])


class MixEnv(gym.Env):
    """The envs of a `Mix` behind one Gymnasium interface (module docstring); `info["cell"]` names the episode's
    cell at reset. The observation and action spaces are the cells' (all equal)."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": []}

    def __init__(self, mix: Mix) -> None:
        self.mix = mix
        self._envs: dict[str, Any] = {}
        self.env = self._env(*mix.cells[0])
        self.observation_space, self.action_space = self.env.observation_space, self.env.action_space
        self._rng = np.random.default_rng()

    def _env(self, label: str, config: CrowdNavConfig) -> Any:
        if label not in self._envs:
            from envs.env import CrowdNavEnv

            self._envs[label] = CrowdNavEnv(config)
        return self._envs[label]

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict]:
        super().reset(seed=seed)
        if seed is not None:
            self._rng = np.random.default_rng(seed)
            episode = int(seed)
        else:
            episode = int(self._rng.integers(MIX_SEED_LOW, MIX_SEED_HIGH))
        label, config = self.mix.cell_of(episode)
        self.env = self._env(label, config)
        obs, info = self.env.reset(seed=episode, options=options)
        return obs, {**info, "cell": label}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict]:
        return self.env.step(action)

    def close(self) -> None:
        for env in self._envs.values():
            env.close()
