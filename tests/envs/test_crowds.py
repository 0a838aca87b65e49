"""The crowds room builds a crowd from what `CrowdSetting` lists, not from the env config itself."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from envs.config import CrowdNavConfig
from envs.crowds.models import make_crowd


def test_make_crowd_reads_only_the_crowd_setting():
    """A plain object with the protocol's fields gives the very crowd the env config gives (same seed, same state)."""
    config = CrowdNavConfig(scenario="plaza", n_pedestrians=6)
    plain = SimpleNamespace(scenario=config.scenario, crowd_model=config.crowd_model, dt_s=config.dt_s, replay=None,
                            sim_config=config.sim_config)
    ours, theirs = make_crowd(config), make_crowd(plain)
    a, b = ours.reset(3), theirs.reset(3)
    for _ in range(5):
        a, b = ours.step(), theirs.step()
    assert len(a.pos) == 6
    np.testing.assert_array_equal(a.pos, b.pos)
    np.testing.assert_array_equal(a.group_id, b.group_id)
