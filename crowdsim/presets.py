"""Domain randomisation: named, versioned training presets that draw each recording's parameters.

A `Randomization` holds ranges; `sample_config(preset, scenario, seed)` draws one `SimConfig` from them with a
Generator seeded by (preset name, version, scenario, recording seed), so a recording's parameters depend on
nothing else (not on the other recordings, the worker count or the backend). Every range is uniform and
inclusive; an integer range draws integers. The drawn config goes into each recording's JSON metadata.

Ranges of `realistic-v1` and where they come from:
- Desired speed mean 1.20–1.45 m/s (Weidmann 1993: 1.34 m/s free speed; Moussaïd et al. 2010 saw ~1.3 m/s
  for singles in a shopping street), within-population sd 0.20–0.30 m/s.
- Group sizes: zero-truncated Poisson rate 0.6–1.6, i.e. 45–80 % of people in groups (Moussaïd et al. 2010
  counted up to 70 % in groups in a commercial street; train stations have fewer).
- Walking spacing 0.65–0.90 m between neighbours abreast (Zanlungo et al. 2014–2015: ~0.75 m for pairs at low
  density, shrinking with density); body radii 0.20–0.30 m.
- Behaviour mix: stops, meeting and parting at stops, leave and merge events, strangers walking close, each
  from off to a rate where it shapes the scene (`BehaviourConfig`).
- Crowd size per scenario, so that densities range from sparse to about 0.6 persons/m².
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field, replace

import numpy as np

from crowdsim.config import BehaviourConfig, GroupConfig, SimConfig, SocialForceParams
from crowdsim.names import unknown_name

Range = tuple[float, float]


@dataclass(frozen=True)
class Randomization:
    """Per-recording parameter ranges (lo, hi), units as in the config field each one sets."""

    pedestrians: dict[str, tuple[int, int]]  # scenario -> crowd size range
    scenario_options: dict[str, dict[str, Range]] = field(default_factory=dict)  # scenario -> option -> range
    desired_speed_mean_mps: Range = (1.20, 1.45)
    desired_speed_std_mps: Range = (0.20, 0.30)
    size_poisson_rate: Range = (0.6, 1.6)
    formation_spacing_m: Range = (0.65, 0.90)
    radius_min_m: Range = (0.20, 0.24)
    radius_max_m: Range = (0.26, 0.30)
    leave_rate_hz: Range = (0.0, 0.01)
    merge_rate_hz: Range = (0.0, 0.01)
    stop_rate_hz: Range = (0.0, 0.03)
    stop_mean_s: Range = (20.0, 60.0)
    join_rate_hz: Range = (0.0, 0.1)
    part_rate_hz: Range = (0.0, 0.02)
    stranger_companion_prob: Range = (0.0, 0.5)

    def __post_init__(self) -> None:
        for name, value in self.__dict__.items():
            ranges = value.values() if name == "pedestrians" else [value] if isinstance(value, tuple) else []
            for lo, hi in ranges:
                if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
                    raise ValueError(f"range {name} must have lo <= hi, got ({lo}, {hi})")


@dataclass(frozen=True)
class Preset:
    """A named, versioned training preset: its scenarios and the ranges each recording is drawn from."""

    name: str
    version: int
    description: str
    scenarios: tuple[str, ...]
    randomization: Randomization


REALISTIC_V1 = Preset(
    name="realistic-v1",
    version=1,
    description="corridor, crossing, plaza and circle crossing; sparse to ~0.6 /m2; stops, meetings, strangers",
    scenarios=("corridor", "crossing", "plaza", "circle_crossing"),
    randomization=Randomization(
        pedestrians={"corridor": (8, 45), "crossing": (10, 45), "plaza": (12, 70), "circle_crossing": (5, 20)},
        scenario_options={"corridor": {"width_m": (3.0, 6.0)}, "plaza": {"size_m": (16.0, 26.0)}},
    ),
)

PRESETS: dict[str, Preset] = {REALISTIC_V1.name: REALISTIC_V1}


def get_preset(name: str) -> Preset:
    if name not in PRESETS:
        raise ValueError(unknown_name("preset", name, sorted(PRESETS)))
    return PRESETS[name]


def _rng(preset: Preset, scenario: str, seed: int) -> np.random.Generator:
    digest = hashlib.sha256(f"{preset.name}/{preset.version}/{scenario}/{seed}".encode()).digest()
    return np.random.default_rng(int.from_bytes(digest[:8], "little"))


def sample_config(preset: Preset, scenario: str, seed: int) -> SimConfig:
    """The SimConfig of recording `seed` of `scenario` under `preset` (ValueError for a scenario the preset
    does not cover)."""
    if scenario not in preset.scenarios:
        raise ValueError(f"preset {preset.name} has no scenario {scenario!r}; its scenarios: "
                         f"{', '.join(preset.scenarios)}")
    r, rng = preset.randomization, _rng(preset, scenario, seed)

    def draw(lo_hi: Range) -> float:
        return float(rng.uniform(*lo_hi))

    lo, hi = r.pedestrians[scenario]
    n = int(rng.integers(lo, hi + 1))
    options = tuple((k, round(draw(v), 3)) for k, v in sorted(r.scenario_options.get(scenario, {}).items()))
    social = replace(SocialForceParams(), desired_speed_mean_mps=draw(r.desired_speed_mean_mps),
                     desired_speed_std_mps=draw(r.desired_speed_std_mps))
    groups = GroupConfig(size_poisson_rate=draw(r.size_poisson_rate), max_size=min(5, n),
                         formation_spacing_m=draw(r.formation_spacing_m), leave_rate_hz=draw(r.leave_rate_hz),
                         merge_rate_hz=draw(r.merge_rate_hz))
    behaviour = BehaviourConfig(stop_rate_hz=draw(r.stop_rate_hz), stop_mean_s=draw(r.stop_mean_s),
                                join_rate_hz=draw(r.join_rate_hz), part_rate_hz=draw(r.part_rate_hz),
                                stranger_companion_prob=draw(r.stranger_companion_prob))
    return SimConfig(scenario=scenario, n_pedestrians=n, radius_min_m=draw(r.radius_min_m),
                     radius_max_m=draw(r.radius_max_m), social=social, groups=groups, behaviour=behaviour,
                     scenario_options=options)
