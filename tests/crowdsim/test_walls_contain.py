"""Nobody is ever outside the walls: group spawns never place a member beyond a wall (a disc on the far side
of a wall also "clears" it), and the wall-crossing test behind that check."""

from __future__ import annotations

import numpy as np

from crowdsim import CrowdSimulator, GroupConfig, SimConfig
from crowdsim.forces import crossed_walls


def test_crossed_walls_counts_proper_crossings_only():
    wall = np.array([[[0.0, 0.0], [10.0, 0.0]]])
    start = np.array([[1.0, 1.0], [1.0, 1.0], [1.0, 1.0], [-1.0, 1.0], [1.0, 0.0]])
    end = np.array([[1.0, -1.0], [2.0, 0.5], [1.0, 0.0], [-1.0, -1.0], [5.0, 0.0]])
    # through; stays on one side; ends on the wall (touch); passes beyond the wall's end; runs along it
    np.testing.assert_array_equal(crossed_walls(start, end, wall), [True, False, False, False, False])
    assert crossed_walls(start, end, np.zeros((0, 2, 2))).shape == (5,)


def test_dense_grouped_corridor_keeps_everyone_between_its_walls():
    """Groups of up to 5 abreast (up to 3 m wide) spawning in a 4 m corridor under continuous inflow."""
    width = 4.0
    sim = CrowdSimulator(SimConfig(scenario="corridor", n_pedestrians=60, groups=GroupConfig(max_size=5),
                                   scenario_options=(("length_m", 20.0), ("width_m", width))))
    for seed in range(3):
        state = sim.reset(seed=seed)
        for _ in range(150):
            y = state.pos[state.active, 1]
            assert np.all((y > 0.0) & (y < width)), (seed, state.frame, y[(y <= 0) | (y >= width)])
            state = sim.step()


def test_a_group_drawn_beside_a_wall_is_not_spawned_through_it(monkeypatch):
    """Three abreast (0.75 m apart) around an origin 0.4 m from the wall: the outer member would stand 0.35 m
    beyond it, which clears the wall by more than its radius. Such a placement must be refused."""
    from crowdsim.scenarios import Scenario

    sim = CrowdSimulator(SimConfig(scenario="corridor", n_pedestrians=6, groups=GroupConfig(max_size=3),
                                   scenario_options=(("length_m", 20.0), ("width_m", 10.0))))
    sim.reset(seed=0)
    monkeypatch.setattr(Scenario, "draw_flow", lambda self, rng: (np.array([10.0, 0.4]), np.array([30.0, 0.4])))
    before = sim.slots.active.sum()
    for _ in range(5):
        sim._try_spawn_group(3, 0.0, tries=1)
    active = sim.slots.active
    assert active.sum() == before  # every attempt refused: no member was placed beyond the wall
    assert np.all(sim.slots.pos[active, 1] > 0.0)
