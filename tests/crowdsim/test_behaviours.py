"""Stops in F-formations, meeting and parting at a stop, strangers who walk close, variation inside groups."""

from __future__ import annotations

import numpy as np
import pytest

from crowdsim.behaviours import assign_places, fformation
from crowdsim.config import BehaviourConfig, GroupConfig, SimConfig
from crowdsim.sim import CrowdSimulator

STOPPING = BehaviourConfig(stop_rate_hz=0.05, stop_mean_s=30.0)


@pytest.mark.parametrize("n", [2, 3, 4, 5])
def test_fformation_puts_neighbours_at_the_spacing_on_a_circle(n):
    centre = np.array([3.0, -1.0])
    places = fformation(n, centre, 0.9, phase=0.3)
    radii = np.linalg.norm(places - centre, axis=1)
    assert np.allclose(radii, radii[0])
    gaps = np.linalg.norm(places - np.roll(places, 1, axis=0), axis=1)
    assert np.allclose(gaps, 0.9) if n > 2 else gaps[0] == pytest.approx(0.9)
    moved = assign_places(places[::-1] + 0.05, places, centre)  # members already near their places keep them
    assert np.allclose(moved, places[::-1])


def run(config: SimConfig, seed: int, steps: int):
    sim = CrowdSimulator(config)
    sim.reset(seed)
    return sim, [sim.step() for _ in range(steps)]


def test_stopped_groups_stand_still_in_their_fformation_and_then_walk_on():
    sim = CrowdSimulator(SimConfig(scenario="plaza", n_pedestrians=24, behaviour=STOPPING))
    sim.reset(0)
    spacing = STOPPING.fformation_spacing_m
    standing_speeds, radius_errors, ended = [], [], 0
    watch: dict[int, float] = {}  # label -> when its stop ended
    for _ in range(900):
        before = {lb for lb, st in sim.book.stops.items() if st.standing}
        state = sim.step()
        for label in before - set(sim.book.stops):
            watch[int(label)] = state.time_s
            ended += 1
        for label, stop in sim.book.stops.items():
            members = state.active & (state.label == label)
            if not stop.standing or state.time_s - stop.since_s < 4.0 or members.sum() < 2:
                continue
            n = int(members.sum())
            design = spacing / 2 if n == 2 else spacing / (2 * np.sin(np.pi / n))
            radius_errors.append(np.linalg.norm(state.pos[members] - stop.centre, axis=1).mean() - design)
            standing_speeds.extend(np.linalg.norm(state.vel[members], axis=1))
    assert len(standing_speeds) > 500 and ended >= 5
    assert np.median(standing_speeds) < 0.1  # they stand (body sway from the fluctuation force aside)
    assert abs(np.median(radius_errors)) < 0.15  # in the circle they were given
    # groups whose stop ended walked on: they are either gone through an exit, moving at walking pace or stopped
    # again (on their way to, or standing at, a new stop)
    state = sim.state()
    for label in watch:
        members = state.active & (state.label == label)
        if members.any() and state.time_s - watch[label] > 5.0 and label not in sim.book.stops:
            assert np.linalg.norm(state.vel[members], axis=1).mean() > 0.5


def test_no_stops_unless_configured():
    sim, _ = run(SimConfig(scenario="plaza", n_pedestrians=24), 0, 300)
    assert not sim.book.stops and sim.book.next_label > 24  # plenty of groups came and none stopped


def test_singles_join_standing_groups_and_members_part_with_new_labels():
    cfg = BehaviourConfig(stop_rate_hz=0.05, join_rate_hz=0.2, part_rate_hz=0.02)
    sim = CrowdSimulator(SimConfig(scenario="plaza", n_pedestrians=30, behaviour=cfg))
    state = sim.reset(1)
    joined, parted = 0, 0
    for _ in range(900):
        old = dict(zip(state.ped_id[state.active].tolist(), state.label[state.active].tolist(), strict=True))
        sizes_before = {lb: int(np.sum(state.active & (state.label == lb))) for lb in set(old.values())}
        state = sim.step()
        for ped, label in zip(state.ped_id[state.active].tolist(), state.label[state.active].tolist(), strict=True):
            if ped in old and old[ped] != label:
                if sizes_before[old[ped]] == 1 and label in sim.book.stops:
                    joined += 1  # a single took a standing group's label
                elif label >= sim.book.next_label - 5 and np.sum(state.label == label) == 1:
                    parted += 1  # a member left with a fresh label of its own
    assert joined >= 3 and parted >= 3


@pytest.mark.slow
def test_strangers_enter_close_enough_that_distance_alone_calls_them_a_group():
    """With every arriving single placed beside or behind the last group, many pairs of people with
    different labels stay within 1.5 m for 8 consecutive recorded steps (3.2 s): the distance rule that
    finds groups in a crowd without strangers makes false pairs here. Seeds 2-16 pooled: 714 false pairs
    without strangers, 1605 with strangers who keep pace with their group, 1493 with strangers who walk at their
    own speed (stranger_follow_gain_per_s 0: they drift away). Keeping pace adds ~17 false pairs per seed (seeds
    17-46: 16.3 +- 3.9; 19.9 +- 3.9 before groups of 4-5 looked round at their other row), too few to show on the
    3 seeds this test used to pool: their ratio was 1.35 before that change reshuffled the runs and 0.99 after,
    and the old model's own seeds 5-7 gave 0.92 (~12 s). Since members stopped repelling each other as strangers
    do (`GroupForceParams.member_ped_repulsion_scale` = 0, d0 = 0.6 m, share 0.6) the tighter groups leave more
    chance encounters within 1.5 m even without strangers: 958, 1715, 1516 (ratio 1.79, was 2.25; the member
    change alone at the old d0: 903, 1704, 1392, ratio 1.89), hence 1.5 for "strangers nearly double them"."""
    base = dict(scenario="plaza", n_pedestrians=24)
    false_pairs = []
    for prob, gain in ((0.0, 0.5), (1.0, 0.5), (1.0, 0.0)):
        behaviour = BehaviourConfig(stranger_companion_prob=prob, stranger_follow_gain_per_s=gain)
        false_pairs.append(sum(_false_pairs(SimConfig(behaviour=behaviour, **base), seed) for seed in range(2, 17)))
    assert false_pairs[1] > 1.5 * false_pairs[0], false_pairs
    assert false_pairs[1] > 1.05 * false_pairs[2], false_pairs  # keeping pace is what keeps them close


def _false_pairs(config: SimConfig, seed: int) -> int:
    """Pairs of people with different labels who stayed within 1.5 m for 8 consecutive steps in 400 steps."""
    _, states = run(config, seed, 400)
    close: dict[tuple[int, int], int] = {}
    pairs = set()
    for s in states:
        act = np.flatnonzero(s.active)
        d = np.linalg.norm(s.pos[act, None] - s.pos[None, act], axis=2)
        i, j = np.nonzero(np.triu(d < 1.5, 1))
        now = {(int(s.ped_id[act[a]]), int(s.ped_id[act[b]])) for a, b in zip(i, j, strict=True)
               if s.label[act[a]] != s.label[act[b]]}
        close = {p: close.get(p, 0) + 1 for p in now}
        pairs |= {p for p, k in close.items() if k >= 8}
    return len(pairs)


def test_members_of_a_group_differ_slightly_in_desired_speed():
    sim, _ = run(SimConfig(scenario="plaza", n_pedestrians=40), 3, 50)
    act = np.flatnonzero(sim.slots.active)
    spreads = [np.std(sim.slots.speed[act[sim.slots.label[act] == lb]]) for lb in np.unique(sim.slots.label[act])
               if np.sum(sim.slots.label[act] == lb) >= 2]
    assert 0.01 < np.mean(spreads) < 0.1


def _triple_shapes(n: int, seed: int = 0, steps: int = 300) -> tuple[dict[str, float], float]:
    """Shares of walking triples abreast / V (middle member behind) / river (deeper than wide), and the
    median angle of pairs to the walking direction (90 = abreast), in a 40 x 4 m two-way corridor."""
    config = SimConfig(scenario="corridor", n_pedestrians=n, groups=GroupConfig(size_poisson_rate=1.5, max_size=3),
                       scenario_options=(("length_m", 40.0), ("width_m", 4.0)))
    _, states = run(config, seed, steps)
    shapes, angles = [], []
    for s in states[60:]:
        act = np.flatnonzero(s.active & (s.pos[:, 0] > 5.0) & (s.pos[:, 0] < 35.0))
        for label in np.unique(s.label[act]):
            m = act[s.label[act] == label]
            v = s.vel[m].mean(axis=0)
            if np.linalg.norm(v) < 0.2 or len(m) == 1:
                continue
            e = v / np.linalg.norm(v)
            fwd, lat = np.array([e, [-e[1], e[0]]]) @ (s.pos[m] - s.pos[m].mean(axis=0)).T
            if len(m) == 2:
                angles.append(np.degrees(np.arctan2(abs(lat[1] - lat[0]), abs(fwd[1] - fwd[0]))))
                continue
            left, mid, right = np.argsort(lat)
            if np.ptp(fwd) > np.ptp(lat):
                shapes.append("river")
            elif fwd[mid] < min(fwd[left], fwd[right]) - 0.2:
                shapes.append("V")
            else:
                shapes.append("abreast")
    kinds, counts = np.unique(shapes, return_counts=True)
    return dict(zip(kinds.tolist(), (counts / counts.sum()).tolist(), strict=True)), float(np.median(angles))


def test_formations_change_with_density_from_abreast_to_v_and_river():
    """Moussaïd et al. 2010: at low density pairs and triples walk abreast; as density rises, pairs fall
    back into a slanted line and triples bend into a V (middle member behind) or a river-like file.
    (Emergent from the group forces and the crowd, not scripted; four seeds each.) Measured on seeds 0-5: the
    median pair angle falls from 88.5 to 74.8 deg, triples abreast 0.92 -> 0.63, river 0.03 -> 0.26, V 0.05 ->
    0.11. The catch-up term (GroupForceParams.catch_up_strength) stiffened this: without it, 87 -> 60 deg and
    V 0.40 -> 0.21 (more V at low density than Moussaïd et al. saw). The thresholds are not field data."""
    sparse = [_triple_shapes(12, seed) for seed in range(4)]
    dense = [_triple_shapes(90, seed) for seed in range(4)]

    def share(runs, kind):
        return float(np.mean([shapes.get(kind, 0.0) for shapes, _ in runs]))

    sparse_angle, dense_angle = (float(np.mean([a for _, a in runs])) for runs in (sparse, dense))
    assert sparse_angle > 80.0 and dense_angle < sparse_angle - 10.0, (sparse_angle, dense_angle)
    # sparse: abreast is the commonest shape of a triple (a V also occurs: members' speeds differ a little)
    assert share(sparse, "abreast") > max(share(sparse, "V"), share(sparse, "river")), sparse
    assert share(dense, "abreast") < share(sparse, "abreast") - 0.05, (sparse, dense)
    assert share(dense, "river") > share(sparse, "river") + 0.15, (sparse, dense)


def test_groups_above_three_look_mostly_at_their_own_row_and_the_front_row_is_held_back_a_little():
    from crowdsim import forces
    from crowdsim.config import GroupForceParams
    from crowdsim.groups import gaze_subgroups

    pos = np.array([[1.0, 0.4], [1.0, -0.4], [0.0, 0.4], [0.0, -0.4], [5.0, 5.0], [5.0, 5.8]])
    goal = pos + np.array([10.0, 0.0])
    label = np.array([0, 0, 0, 0, 1, 1])
    sub = gaze_subgroups(pos, goal, label)
    assert sub[0] == sub[1] != sub[2] == sub[3] and sub[4] == sub[5] and len(set(sub.tolist())) == 3
    vel = np.tile([1.2, 0.0], (6, 1))
    e = vel / 1.2
    none = np.zeros(0, np.int64)
    params = GroupForceParams()
    whole = forces.group_acc(pos, vel, e, label, none, none, params)
    own_row = forces.group_acc(pos, vel, e, label, none, none, GroupForceParams(whole_group_gaze_share=0.0),
                               gaze_label=sub)
    rows = forces.group_acc(pos, vel, e, label, none, none, params, gaze_label=sub)
    assert whole[0, 0] < -0.5 and whole[1, 0] < -0.5  # looking round at the row behind brakes the front row
    assert own_row[0, 0] == pytest.approx(0.0, abs=1e-9) and own_row[1, 0] == pytest.approx(0.0, abs=1e-9)
    share = params.whole_group_gaze_share
    assert 0.0 < share < 1.0
    np.testing.assert_allclose(rows[:4], (1.0 - share) * own_row[:4] + share * whole[:4], rtol=1e-12, atol=1e-12)
    assert whole[0, 0] < rows[0, 0] < -0.05  # the front row waits for the back one, a little
    assert rows[2, 0] > 0.05  # and the back row catches up
    np.testing.assert_array_equal(rows[4:], whole[4:])  # a pair is one row: unaffected
