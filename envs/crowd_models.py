"""The crowd models a `CrowdNavConfig.crowd_model` names: a small explicit registry (name -> builder).

    social-force  crowdsim's pymunk social-force crowd with groups (the default; `envs.crowd.SimCrowd`)
    orca          CrowdNav's ORCA humans on a circle, for comparability with the CrowdNav literature
                  (`envs.orca_crowd.OrcaCrowd`; needs the optional package pyrvo)

A replay (scenario "replay") is not a crowd model: the recording is the crowd. `make_crowd` builds either.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from crowdsim.names import unknown_name

if TYPE_CHECKING:
    from envs.config import CrowdNavConfig

DEFAULT_CROWD_MODEL = "social-force"
ORCA_SCENARIOS = ("circle_crossing",)  # ORCA here knows no walls: the only scenario without walls and flows


def _social_force(cfg: CrowdNavConfig) -> Any:
    from envs.crowd import SimCrowd

    return SimCrowd(cfg.sim_config())


def _orca(cfg: CrowdNavConfig) -> Any:
    from envs.orca_crowd import OrcaCrowd

    return OrcaCrowd(cfg)


CROWD_MODELS: dict[str, Callable[[CrowdNavConfig], Any]] = {"social-force": _social_force, "orca": _orca}


def check_crowd_model(name: str, scenario: str) -> None:
    """ValueError (one line) for an unknown crowd model, naming the valid ones, or for ORCA in a scenario it cannot
    run (walls)."""
    if name not in CROWD_MODELS:
        raise ValueError(unknown_name("crowd model", name, CROWD_MODELS))
    if name == "orca" and scenario not in ORCA_SCENARIOS:
        raise ValueError(f"crowd model 'orca' runs only scenario {', '.join(ORCA_SCENARIOS)} (ORCA here has no "
                         f"walls), not {scenario!r}")


def make_crowd(cfg: CrowdNavConfig) -> Any:
    """The env's `envs.crowd.Crowd` for a config: its crowd model, or a replayed file for scenario 'replay'."""
    from envs.config import REPLAY_SCENARIO

    if cfg.scenario == REPLAY_SCENARIO:
        from envs.replay import ReplayCrowd

        return ReplayCrowd(replace(cfg.replay, dt_s=cfg.dt_s))
    return CROWD_MODELS[cfg.crowd_model](cfg)
