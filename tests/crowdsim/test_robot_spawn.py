"""New pedestrians never appear on top of a visible robot; an invisible one changes nothing in the crowd."""

from __future__ import annotations

import numpy as np

from crowdsim import CrowdSimulator, RobotSlot, SimConfig


def test_no_pedestrian_spawns_within_contact_of_a_visible_robot():
    sim = CrowdSimulator(SimConfig(scenario="corridor", n_pedestrians=30, robot=RobotSlot(visible=True)))
    sim.reset(seed=3)
    spot = np.array([0.75, 2.0])  # inside the west-east flow's spawn area (x 0..1.5 m, y 0.4..3.6 m)
    seen = set(sim.state().ped_id[sim.state().active].tolist())
    new_count = 0
    for _ in range(600):
        sim.set_robot(spot, np.zeros(2), 0.3)
        state = sim.step()
        act = state.active
        for pid, pos, r in zip(state.ped_id[act], state.pos[act], state.radius[act], strict=True):
            if int(pid) in seen:
                continue
            seen.add(int(pid))
            new_count += 1
            assert np.linalg.norm(pos - spot) > r + 0.3, f"pedestrian {pid} appeared on the robot"
    assert new_count > 20  # the flow kept spawning around it
