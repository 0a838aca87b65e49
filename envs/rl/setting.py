"""Where an agent trains: a benchmark suite's cell as the training env, seeds that no suite reports, and the
decision period (the agent acts every k env steps and holds its action in between).

- `suite_env_config(suite, cell)`: the env config of a simulated cell of `envs/evaluation/suites/<suite>.json`
  (`envs.evaluation.suite.Cell.env_config`), e.g. crowdnav-classic's ORCA crowd, holonomic robot, 0.05 s steps.
  Replay cells (recorded crowds) are refused: training on the recordings a suite reports would leak them.
- `suite_seed_ranges()` / `check_seeds(what, seeds)`: a suite's episode i is `env.reset(seed=seed0 + i)`, so a
  training or model-selection episode drawn from the same seed would be a reported episode. Training resets use
  seeds from `TRAIN_SEED_OFFSET` on (SB3 resets env i of the vector with seed + i), and every other seed range
  of a run (evaluation, demonstrations) is checked against every shipped suite's seeds.
- `DecisionPeriod`: a Gymnasium wrapper that repeats the agent's action for `every` env steps (CrowdNav decides
  every 0.25 s, 5 steps of 0.05 s), summing the rewards and stopping as soon as the episode ends.
"""

from __future__ import annotations

import argparse
import json
from functools import lru_cache
from importlib import resources
from typing import Any

import gymnasium as gym

from envs.config import CrowdNavConfig

# Training resets draw their episodes from seeds TRAIN_SEED_OFFSET + seed + i (env i of the vector): far above
# every suite's seeds (at most a few thousand) and the default evaluation (100000+) and demonstration (200000+) seeds.
TRAIN_SEED_OFFSET = 10_000_000
MAX_SEED = 2**32 - 1  # numpy's seed bound


@lru_cache(maxsize=1)
def suite_seed_ranges() -> tuple[tuple[str, range], ...]:
    """("suite/cell", seeds) of every cell of every shipped suite, read from the suite files' seed0/episodes."""
    out = []
    for entry in sorted(resources.files("envs.evaluation.suites").iterdir(), key=lambda p: p.name):
        if not entry.name.endswith(".json"):
            continue
        data = json.loads(entry.read_text())
        for c in data["cells"]:
            seed0 = int(c["seed0"])
            out.append((f"{data['name']}/{c['name']}", range(seed0, seed0 + int(c["episodes"]))))
    return tuple(out)


def _overlap(a: range, b: range) -> range:
    return range(max(a.start, b.start), min(a.stop, b.stop))


def check_seeds(what: str, seeds: range) -> None:
    """ValueError when `seeds` (a range of reset seeds) is not inside [0, 2^32) or meets any suite's seeds."""
    if seeds.start < 0 or seeds.stop - 1 > MAX_SEED:
        raise ValueError(f"{what}: seeds {seeds.start}..{seeds.stop - 1} must lie in 0..{MAX_SEED}")
    hits = [(name, _overlap(seeds, r)) for name, r in suite_seed_ranges() if len(_overlap(seeds, r))]
    if hits:
        name, common = hits[0]
        more = f" (and {len(hits) - 1} more cells)" if len(hits) > 1 else ""
        raise ValueError(f"{what}: seeds {seeds.start}..{seeds.stop - 1} include the reported episodes "
                         f"{common.start}..{common.stop - 1} of suite cell {name}{more}; choose seeds outside the "
                         f"suites' {', '.join(f'{r.start}..{r.stop - 1}' for r in _merged())}")


def _merged() -> list[range]:
    """The suites' seed ranges merged where they overlap or touch, in order."""
    out: list[range] = []
    for r in sorted((r for _, r in suite_seed_ranges()), key=lambda r: r.start):
        if out and r.start <= out[-1].stop:
            out[-1] = range(out[-1].start, max(out[-1].stop, r.stop))
        else:
            out.append(r)
    return out


def check_disjoint(ranges: dict[str, range]) -> None:
    """ValueError when two of the named seed ranges share a seed."""
    items = [(k, r) for k, r in ranges.items() if len(r)]
    for i, (a, ra) in enumerate(items):
        for b, rb in items[i + 1:]:
            if len(_overlap(ra, rb)):
                raise ValueError(f"{a} {ra.start}..{ra.stop - 1} and {b} {rb.start}..{rb.stop - 1} share seeds; "
                                 "a run's training, evaluation and demonstration episodes must differ")


@lru_cache(maxsize=16)
def suite_env_config(suite: str, cell: str = "") -> tuple[str, CrowdNavConfig]:
    """(cell name, env config) of a simulated cell of a shipped suite; `cell` "" names a suite's only cell.
    ValueError listing the valid names for an unknown suite or cell, and for a replay cell."""
    from envs.evaluation.suite import load_suite

    s = load_suite(suite)
    if not cell:
        if len(s.cells) != 1:
            raise ValueError(f"suite {suite} has {len(s.cells)} cells; name one with --cell: "
                             + ", ".join(c.name for c in s.cells))
        cell = s.cells[0].name
    c = s.cell(cell)
    if c.is_real:
        simulated = [x.name for x in s.cells if not x.is_real]
        raise ValueError(f"cell {cell} of suite {suite} replays recorded crowds, which training does not use (the "
                         f"recordings are what the suite reports); simulated cells: {', '.join(simulated) or 'none'}")
    return c.name, c.env_config(c.seeds[0])


class DecisionPeriod(gym.Wrapper):
    """The agent acts every `every` env steps: `step(action)` steps the env `every` times with the same action
    (stopping at once when the episode terminates or is truncated) and returns the last observation, the sum of
    the rewards, the last termination flags and the last info. `every` 1 is the env itself."""

    def __init__(self, env: gym.Env, every: int = 1) -> None:
        super().__init__(env)
        if not isinstance(every, int) or every < 1:
            raise ValueError(f"every must be an integer >= 1, got {every!r}")
        self.every = every

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict]:
        total = 0.0
        for _ in range(self.every):
            obs, reward, terminated, truncated, info = self.env.step(action)
            total += float(reward)
            if terminated or truncated:
                break
        return obs, total, terminated, truncated, info


def add_setting_arguments(p: argparse.ArgumentParser) -> None:
    """`crowdnav train`'s --suite, --cell, --mix and --decision-every-steps (TrainConfig fields; unset: the
    defaults)."""
    p.add_argument("--suite", type=str, default=argparse.SUPPRESS, dest="suite", metavar="NAME",
                   help="train in a simulated cell of this benchmark suite (envs/evaluation/suites): its crowd model, "
                        "robot, dt and time limit; --scenario, --pedestrians, --invisible and --time-limit-s are then "
                        "errors (evaluate with crowdnav benchmark --suite NAME --policy sb3:OUT/final.zip)")
    p.add_argument("--cell", type=str, default=argparse.SUPPRESS, dest="cell", metavar="NAME",
                   help="the suite's cell (default: its only cell)")
    p.add_argument("--mix", type=str, default=argparse.SUPPRESS, dest="mix", metavar="NAME",
                   help="train a generalist in a mix of suite cells (envs/rl/mix.py MIXES, e.g. crowdnav-v1-train: "
                        "crowdnav-v1's simulated cells and two recorded crowds outside every test split), each "
                        "episode in one of them; instead of --suite and the scenario flags")
    p.add_argument("--decision-every-steps", type=int, default=argparse.SUPPRESS, dest="decision_every_steps",
                   metavar="K", help="env steps per agent decision, the action held in between (e.g. 5 at dt 0.05 s: "
                                     "CrowdNav's 0.25 s); saved with the agent, which sb3: then runs at this period; "
                                     "step counts are then decisions (default: 1)")
