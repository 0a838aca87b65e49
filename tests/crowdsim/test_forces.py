"""Force terms: symmetry, anisotropy, walls, groups and the neighbour index."""

from __future__ import annotations

import numpy as np
import pytest

from crowdsim import forces
from crowdsim.config import GroupForceParams, SocialForceParams
from crowdsim.neighbors import brute_force_pairs, neighbor_pairs


def _random_crowd(n: int, seed: int):
    rng = np.random.default_rng(seed)
    pos = rng.uniform(0, 10, (n, 2))
    e, _ = forces.unit(rng.normal(size=(n, 2)))
    radius = rng.uniform(0.2, 0.3, n)
    return pos, e, radius


def test_pair_forces_are_antisymmetric_without_anisotropy():
    pos, e, radius = _random_crowd(60, 0)
    params = SocialForceParams(anisotropy=1.0)
    i, j = neighbor_pairs(pos, params.cutoff_m)
    acc_i, acc_j = forces.pair_terms(pos[i] - pos[j], radius[i] + radius[j], e[i], e[j], params)
    np.testing.assert_allclose(acc_i, -acc_j, atol=1e-15)
    total = forces.pedestrian_acc(pos, radius, e, i, j, params)
    np.testing.assert_allclose(total.sum(axis=0), 0.0, atol=1e-10)  # no net momentum from interactions


def test_pair_forces_act_along_the_line_of_centres_and_repel():
    pos, e, radius = _random_crowd(40, 1)
    params = SocialForceParams()
    i, j = neighbor_pairs(pos, params.cutoff_m)
    diff = pos[i] - pos[j]
    acc_i, acc_j = forces.pair_terms(diff, radius[i] + radius[j], e[i], e[j], params)
    cross = diff[:, 0] * acc_i[:, 1] - diff[:, 1] * acc_i[:, 0]
    np.testing.assert_allclose(cross, 0.0, atol=1e-12)
    assert np.all(np.einsum("pk,pk->p", acc_i, diff) > 0)  # i is pushed away from j
    assert np.all(np.einsum("pk,pk->p", acc_j, diff) < 0)


def test_anisotropy_weakens_interaction_from_behind():
    params = SocialForceParams(anisotropy=0.3)
    diff = np.array([[1.0, 0.0]])  # j is at -x of i
    ahead = forces.pair_terms(diff, np.array([0.5]), np.array([[-1.0, 0.0]]), np.array([[1.0, 0.0]]), params)[0]
    behind = forces.pair_terms(diff, np.array([0.5]), np.array([[1.0, 0.0]]), np.array([[1.0, 0.0]]), params)[0]
    assert np.linalg.norm(behind) == pytest.approx(0.3 * np.linalg.norm(ahead))


def test_repulsion_decays_exponentially_with_surface_gap():
    params = SocialForceParams()
    e = np.array([[0.0, 1.0]])
    mags = [np.linalg.norm(forces.pair_terms(np.array([[d, 0.0]]), np.array([0.5]), e, e, params)[0])
            for d in (0.6, 0.9)]
    assert mags[0] / mags[1] == pytest.approx(np.exp(0.3 / params.ped_range_m))


def test_wall_pushes_along_its_normal_and_ignores_far_walls():
    params = SocialForceParams()
    wall = np.array([[[0.0, 0.0], [10.0, 0.0]]])
    pos = np.array([[5.0, 0.4], [5.0, 1.0], [5.0, 5.0]])
    acc = forces.wall_acc(pos, np.full(3, 0.25), wall, params)
    assert np.all(acc[:2, 1] > 0) and np.allclose(acc[:, 0], 0.0)
    assert acc[0, 1] > acc[1, 1]
    np.testing.assert_array_equal(acc[2], 0.0)


def test_coherence_pulls_a_straggler_back_and_gaze_slows_the_leader():
    params = GroupForceParams()
    pos = np.array([[0.0, 0.0], [3.0, 0.0]])  # member 1 far ahead along +x
    vel = np.array([[1.0, 0.0], [1.0, 0.0]])
    e = np.array([[1.0, 0.0], [1.0, 0.0]])
    acc = forces.group_acc(pos, vel, e, np.array([0, 0]), np.array([0]), np.array([1]), params)
    assert acc[0, 0] > 0  # the one behind is pulled forward
    assert acc[1, 0] < -params.coherence_strength_mps2  # the leader is pulled back and slowed by gaze
    alone = forces.group_acc(pos, vel, e, np.array([0, 1]), np.array([0]), np.array([1]), params)
    np.testing.assert_array_equal(alone, 0.0)  # singletons feel no group force


def test_catch_up_mirrors_the_gaze_brake_in_a_slanted_pair():
    """A pair 0.75 m apart, member 1 drawn 0.2 m ahead: the one behind speeds up exactly as much as the one
    ahead slows down (no coherence inside (n - 1) / 2 m, repulsion is lateral), so the pair keeps its mean speed."""
    params = GroupForceParams()
    pos = np.array([[0.0, 0.0], [0.2, 0.72]])
    vel = np.array([[1.2, 0.0], [1.2, 0.0]])
    e = np.array([[1.0, 0.0], [1.0, 0.0]])
    none = np.array([], dtype=int)
    acc = forces.group_acc(pos, vel, e, np.array([0, 0]), none, none, params, v_desired=vel)
    assert acc[0, 0] > 0.1 and acc[1, 0] < -0.1
    assert acc[0, 0] == pytest.approx(-acc[1, 0], rel=1e-9)
    gaze_only = forces.group_acc(pos, vel, e, np.array([0, 0]), none, none,
                                 GroupForceParams(catch_up_strength=0.0), v_desired=vel)
    assert gaze_only[0, 0] == 0.0 and gaze_only[1, 0] == pytest.approx(acc[1, 0])  # Moussaïd's model: only the leader


def test_catch_up_does_not_push_a_member_standing_at_its_place():
    """Standing in an F-formation the desired velocity is ~0: swaying towards the others is not amplified."""
    pos = np.array([[0.0, 0.0], [0.9, 0.0]])
    vel = np.array([[0.05, 0.0], [0.0, 0.0]])
    e = np.array([[1.0, 0.0], [1.0, 0.0]])
    none = np.array([], dtype=int)
    acc = forces.group_acc(pos, vel, e, np.array([0, 0]), none, none, GroupForceParams(), v_desired=np.zeros((2, 2)))
    assert acc[0, 0] <= 0.0


def test_group_members_repel_inside_d0():
    params = GroupForceParams()
    pos = np.array([[0.0, 0.0], [0.0, 0.5]])
    vel = np.zeros((2, 2))
    e = np.array([[1.0, 0.0], [1.0, 0.0]])
    acc = forces.group_acc(pos, vel, e, np.array([0, 0]), np.array([0]), np.array([1]), params)
    assert acc[0, 1] < 0 < acc[1, 1]


@pytest.mark.parametrize("n", [0, 1, 2, 50, 400])
def test_cell_grid_finds_exactly_the_brute_force_pairs(n):
    rng = np.random.default_rng(n)
    pos = rng.uniform(-20, 20, (n, 2))
    got = set(zip(*neighbor_pairs(pos, 3.0), strict=True))
    want = set(zip(*brute_force_pairs(pos, 3.0), strict=True))
    assert got == want


def test_speed_cap_only_touches_fast_rows():
    vel = np.array([[3.0, 4.0], [0.3, 0.4]])
    capped = forces.cap_speed(vel, np.array([1.0, 1.0]))
    np.testing.assert_allclose(capped, [[0.6, 0.8], [0.3, 0.4]])


def _stepped(config, seed: int, robot: bool = False):
    """A CrowdSimulator of `config` reset with `seed` and stepped 5 times; with `robot`, a robot 0.6 m beside the
    first active pedestrian."""
    from crowdsim.sim import CrowdSimulator

    sim = CrowdSimulator(config)
    sim.reset(seed)
    for _ in range(5):
        sim.step()
    if robot:
        sim.set_robot(sim.slots.pos[np.flatnonzero(sim.slots.active)[0]] + [0.6, 0.0], [0.5, 0.2], 0.3)
    return sim


def _assert_kernel_matches_reference(sim) -> None:
    fast, _ = sim.accelerations()
    ref, _ = sim.accelerations(reference=True)
    np.testing.assert_allclose(fast, ref, rtol=1e-10, atol=1e-10)


def test_fused_kernel_matches_the_numpy_reference_with_groups_walls_and_robot():
    from crowdsim.config import SimConfig

    sim = _stepped(SimConfig(scenario="plaza", n_pedestrians=60), 0, robot=True)
    fast, idx = sim.accelerations()
    ref, idx_ref = sim.accelerations(reference=True)
    np.testing.assert_array_equal(idx, idx_ref)
    assert np.abs(ref).max() > 1.0  # a busy scene: walls, neighbours, groups and the robot all act
    np.testing.assert_allclose(fast, ref, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("share", [0.0, 0.125, 1.0])
def test_fused_kernel_matches_the_numpy_reference_for_groups_in_two_rows(share):
    from crowdsim.config import GroupConfig, SimConfig

    config = SimConfig(scenario="plaza", n_pedestrians=30, groups=GroupConfig(size_poisson_rate=2.5),
                       group_forces=GroupForceParams(whole_group_gaze_share=share))
    sim = _stepped(config, 1)
    _, labels, gaze = sim._active_index()
    assert (np.bincount(gaze)[gaze] < np.bincount(labels)[labels]).sum() >= 8  # two groups or more in two rows
    _assert_kernel_matches_reference(sim)


@pytest.mark.parametrize("scale", [0.0, 0.5, 1.0])
def test_fused_kernel_matches_the_numpy_reference_with_members_tolerating_each_other(scale):
    from crowdsim.config import GroupConfig, SimConfig

    for scenario in ("plaza", "corridor"):  # the corridor is periodic: ghosts carry their source's group label
        config = SimConfig(scenario=scenario, n_pedestrians=40, groups=GroupConfig(size_poisson_rate=2.5),
                           group_forces=GroupForceParams(member_ped_repulsion_scale=scale))
        _assert_kernel_matches_reference(_stepped(config, 2, robot=True))


def test_members_of_one_group_repel_each_other_by_the_member_scale_only():
    pos = np.array([[0.0, 0.0], [0.7, 0.0], [0.0, 0.7], [0.7, 0.7]])
    e = np.tile([0.0, 1.0], (4, 1))
    radius = np.full(4, 0.25)
    label = np.array([0, 0, 1, -1])  # a pair, someone alone, the robot (in no group: never a member)
    params = SocialForceParams()
    i, j = brute_force_pairs(pos, params.cutoff_m)
    full = forces.pedestrian_acc(pos, radius, e, i, j, params)
    same = (label[i] == label[j]) & (label[i] >= 0)
    assert same.sum() == 1
    none = forces.pedestrian_acc(pos, radius, e, i[~same], j[~same], params)
    np.testing.assert_array_equal(forces.pedestrian_acc(pos, radius, e, i, j, params, label, 1.0), full)
    np.testing.assert_allclose(forces.pedestrian_acc(pos, radius, e, i, j, params, label, 0.0), none, atol=1e-15)
    half = forces.pedestrian_acc(pos, radius, e, i, j, params, label, 0.5)
    np.testing.assert_allclose(half, 0.5 * (full + none), atol=1e-15)
    with pytest.raises(ValueError, match="member_ped_repulsion_scale"):
        GroupForceParams(member_ped_repulsion_scale=1.5)


def test_cell_grid_grows_its_buffer_for_very_dense_clusters():
    pos = np.random.default_rng(9).uniform(0, 2.0, (300, 2))  # every pair is within the cut-off
    i, j = neighbor_pairs(pos, 3.0)
    assert len(i) == 300 * 299 // 2
    assert set(zip(i, j, strict=True)) == set(zip(*brute_force_pairs(pos, 3.0), strict=True))
