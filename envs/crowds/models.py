"""The crowd models a `CrowdNavConfig.crowd_model` names: a small explicit registry (name -> builder).

    social-force  crowdsim's pymunk social-force crowd with groups (the default; `envs.crowds.crowd.SimCrowd`)
    orca          CrowdNav's ORCA humans on a circle, for comparability with the CrowdNav literature
                  (`envs.crowds.orca.OrcaCrowd`; needs the optional package pyrvo)

A replay (scenario "replay") is not a crowd model: the recording is the crowd. `make_crowd` builds either from a
`CrowdSetting` (the env's config is one): the crowds import no env config; the config names its crowd model.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Protocol

from crowdsim.names import unknown_name

if TYPE_CHECKING:
    from crowdsim import SimConfig

DEFAULT_CROWD_MODEL = "social-force"
REPLAY_SCENARIO = "replay"  # the scenario whose crowd is a recording (`envs.crowds.replay.ReplayCrowd`)
ORCA_SCENARIOS = ("circle_crossing",)  # ORCA here knows no walls: the only scenario without walls and flows


class CrowdSetting(Protocol):
    """What `make_crowd` reads of a config (`envs.config.CrowdNavConfig` is one): the scenario, the crowd model's
    name, the env step dt_s (s), the `envs.crowds.replay.ReplayConfig` of scenario "replay" and crowdsim's config
    stepped at dt_s; crowd model "orca" reads the fields of `envs.crowds.orca.OrcaSetting` too."""

    scenario: str
    crowd_model: str
    dt_s: float
    replay: Any

    def sim_config(self) -> SimConfig: ...


def _social_force(cfg: CrowdSetting) -> Any:
    from envs.crowds.crowd import SimCrowd

    return SimCrowd(cfg.sim_config())


def _orca(cfg: CrowdSetting) -> Any:
    from envs.crowds.orca import OrcaCrowd

    return OrcaCrowd(cfg)


CROWD_MODELS: dict[str, Callable[[CrowdSetting], Any]] = {"social-force": _social_force, "orca": _orca}


def check_crowd_model(name: str, scenario: str) -> None:
    """ValueError (one line) for an unknown crowd model, naming the valid ones, or for ORCA in a scenario it cannot
    run (walls)."""
    if name not in CROWD_MODELS:
        raise ValueError(unknown_name("crowd model", name, CROWD_MODELS))
    if name == "orca" and scenario not in ORCA_SCENARIOS:
        raise ValueError(f"crowd model 'orca' runs only scenario {', '.join(ORCA_SCENARIOS)} (ORCA here has no "
                         f"walls), not {scenario!r}")


def make_crowd(cfg: CrowdSetting) -> Any:
    """The env's `envs.crowds.crowd.Crowd` for a config: its crowd model, or a replayed file for scenario 'replay'."""
    if cfg.scenario == REPLAY_SCENARIO:
        from envs.crowds.replay import ReplayCrowd

        return ReplayCrowd(replace(cfg.replay, dt_s=cfg.dt_s))
    return CROWD_MODELS[cfg.crowd_model](cfg)
