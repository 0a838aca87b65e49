"""Group events that make ground-truth labels time-varying: a member leaves, or two groups merge.

Each group draws its events once per recording step from Poisson processes (rates in GroupConfig).
The new labels take effect from the next recorded frame.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from crowdsim.groups import group_speed

if TYPE_CHECKING:
    from crowdsim.sim import CrowdSimulator


def apply_events(sim: CrowdSimulator) -> None:
    """Draw and apply leave and merge events for the current step (no-op when both rates are 0)."""
    cfg = sim.config.groups
    if cfg.leave_rate_hz <= 0 and cfg.merge_rate_hz <= 0:
        return
    dt = sim.config.record_dt_s
    labels = np.unique(sim.slots.label[sim.slots.active])
    p_leave = 1.0 - np.exp(-cfg.leave_rate_hz * dt)
    p_merge = 1.0 - np.exp(-cfg.merge_rate_hz * dt)
    for label in labels:
        u_leave, u_merge = sim.rng.random(2)
        members = np.flatnonzero(sim.slots.active & (sim.slots.label == label))
        if len(members) == 0:
            continue
        if len(members) >= 2 and u_leave < p_leave:
            leave(sim, int(sim.rng.choice(members)))
        elif u_merge < p_merge:
            merge_nearest(sim, int(label))


def leave(sim: CrowdSimulator, slot: int) -> None:
    """Pedestrian in `slot` leaves its group: a new singleton label, its own speed and destination."""
    s = sim.slots
    s.label[slot] = sim._new_label()
    s.speed[slot] = group_speed(sim.rng, 1, sim.config.social, sim.config.groups)
    s.goal[slot] = sim.scenario.new_destination(sim.rng, s.pos[slot])


def merge_nearest(sim: CrowdSimulator, label: int) -> bool:
    """Group `label` absorbs the nearest group walking the same way within merge_distance_m.

    The absorbed members take the label, destination and speed of `label`. Returns whether a merge
    happened.
    """
    s = sim.slots
    act = np.flatnonzero(s.active)
    mine = act[s.label[act] == label]
    others = act[s.label[act] != label]
    if len(others) == 0:
        return False
    centre = s.pos[mine].mean(axis=0)
    heading = s.goal[mine].mean(axis=0) - centre
    best, best_d = -1, sim.config.groups.merge_distance_m
    for other in np.unique(s.label[others]):
        members = others[s.label[others] == other]
        if len(members) + len(mine) > 2 * sim.config.groups.max_size:
            continue
        c = s.pos[members].mean(axis=0)
        d = float(np.linalg.norm(c - centre))
        h = s.goal[members].mean(axis=0) - c
        same_way = float(heading @ h) > 0.7 * np.linalg.norm(heading) * np.linalg.norm(h)
        if d < best_d and same_way:
            best, best_d = int(other), d
    if best < 0:
        return False
    absorbed = others[s.label[others] == best]
    s.label[absorbed] = label
    s.speed[absorbed] = s.speed[mine[0]]
    destination = s.goal[mine].mean(axis=0)
    sim.retarget_group(label, destination)
    return True
