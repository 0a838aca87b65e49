"""Validation of bad input, the scenario registry, and the group-size distribution."""

from __future__ import annotations

import numpy as np
import pytest

from crowdsim.config import GroupConfig, GroupForceParams, SimConfig, SocialForceParams
from crowdsim.groups import draw_group_sizes, formation_offsets
from crowdsim.scenarios import SCENARIOS, Flow, Scenario, make_scenario
from crowdsim.sim import CrowdSimulator
from tests.crowdsim.conftest import max_overlap, run


def test_negative_radius_is_rejected():
    with pytest.raises(ValueError, match="radius_min_m"):
        SimConfig(radius_min_m=-0.2)


def test_group_larger_than_crowd_is_rejected():
    with pytest.raises(ValueError, match="larger than the crowd"):
        SimConfig(n_pedestrians=3, groups=GroupConfig(max_size=5))


@pytest.mark.parametrize("kwargs", [{"relaxation_time_s": 0.0}, {"anisotropy": 1.5},
                                    {"ped_range_m": float("nan")}])
def test_bad_force_parameters_are_rejected(kwargs):
    with pytest.raises(ValueError):
        SocialForceParams(**kwargs)


@pytest.mark.parametrize("share", [-0.1, 1.5, float("nan")])
def test_whole_group_gaze_share_outside_0_1_is_rejected(share):
    with pytest.raises(ValueError, match="whole_group_gaze_share"):
        GroupForceParams(whole_group_gaze_share=share)


def test_physics_sub_step_above_50_ms_is_rejected():
    with pytest.raises(ValueError, match=r"0\.05"):
        SimConfig(force_dt_s=0.2, physics_substeps=2)


def test_spawn_area_across_a_wall_is_rejected():
    wall = np.array([[[5.0, -10.0], [5.0, 10.0]]])
    with pytest.raises(ValueError, match="across the wall"):
        Scenario("bad", wall, (0, 0, 10, 10), (Flow((4.0, 0.0, 6.0, 1.0), (8.0, 0.0, 9.0, 1.0)),))


def test_unknown_scenario_lists_the_valid_names():
    with pytest.raises(ValueError, match="valid names: bottleneck, circle_crossing, corridor, crossing"):
        make_scenario("stadium")
    with pytest.raises(ValueError, match="plaza"):
        CrowdSimulator(SimConfig(scenario="stadium"))


@pytest.mark.parametrize("pos, vel", [([np.nan, 0.0], [0.0, 0.0]), ([0.0, 0.0], [np.inf, 0.0]),
                                      ([0.0, 0.0, 0.0], [0.0, 0.0])])
def test_bad_robot_state_raises_before_anything_moves(pos, vel):
    sim = CrowdSimulator(SimConfig(n_pedestrians=5, groups=GroupConfig(max_size=2)))
    before = sim.reset(0)
    with pytest.raises(ValueError, match="robot"):
        sim.set_robot(np.array(pos), np.array(vel))
    np.testing.assert_array_equal(sim.state().pos, before.pos)


def test_default_group_sizes_follow_observed_crowds():
    sizes = np.array(draw_group_sizes(np.random.default_rng(0), 20000, GroupConfig()))
    people = np.bincount(sizes, weights=sizes)[1:] / sizes.sum()
    assert 1.0 - people[0] >= 0.5  # at least half of the pedestrians walk in groups
    assert people[1] + people[2] > people[3:].sum()  # mostly pairs and triples
    groups = np.bincount(sizes)[1:]
    assert groups[1] == max(groups[1:])  # pairs are the most common group


def test_formations_are_abreast_up_to_three():
    np.testing.assert_allclose(formation_offsets(3, 0.75)[:, 0], 0.0)
    assert np.ptp(formation_offsets(5, 0.75)[:, 0]) > 0  # two rows above three


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_every_scenario_runs_clean_and_keeps_labels_consistent(name):
    sim, states = run(SimConfig(scenario=name, n_pedestrians=30), seed=4, steps=60)
    ids_seen: dict[int, int] = {}
    for s in states:
        act = s.active
        assert np.all(np.isfinite(s.pos[act])) and np.all(np.isnan(s.pos[~act]))
        assert len(np.unique(s.ped_id[act])) == act.sum()
        g = s.group_id[act]
        assert set(np.unique(g)) == set(range(g.max() + 1))  # dense 0..G-1
        # transient overlaps when groups meet head-on: at most 0.058 m over seeds 0-11 in the corridor, 0.061 since
        # groups of 4-5 look round at their other row (two triples meeting, this seed)
        assert max_overlap(s) < 0.07
        for pid in s.ped_id[act]:
            ids_seen.setdefault(int(pid), s.frame)
    if sim.scenario.continuous:
        assert states[-1].n_active >= 0.8 * 30  # inflow replaces those who left
        assert sim.n_exited > 0 and max(ids_seen) > 30  # new ids are issued, never reused


def test_plaza_runs_for_long_recordings_without_draining():
    sim, states = run(SimConfig(scenario="plaza", n_pedestrians=20), seed=0, steps=750)  # 5 minutes
    counts = [s.n_active for s in states[100:]]
    # a group waits for room for all of it, so a few places stay free for a while: the fewest present over seeds 0-7
    # were 13-16 (12-16 since groups of 4-5 look round at their other row; 13 on this seed), the mean 19.2-19.4
    assert min(counts) >= 12 and np.mean(counts) > 18.5 and sim.n_exited > 60
