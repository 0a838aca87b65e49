"""Group events that make ground-truth labels time-varying: a member leaves, or two groups merge.

Each group draws its events once per recording step from Poisson processes (rates in GroupConfig).
The new labels take effect from the next recorded frame. The functions change the simulator's slots and
take new labels from its group book; they never see the simulator itself.
"""

from __future__ import annotations

import numpy as np

from crowdsim.config import SimConfig
from crowdsim.groups import GroupBook, formation_goals, group_speed, step_probability
from crowdsim.scenarios import Scenario
from crowdsim.state import Slots


def apply_events(slots: Slots, book: GroupBook, rng: np.random.Generator, config: SimConfig,
                 scenario: Scenario) -> None:
    """Draw and apply leave and merge events for the current step (no-op when both rates are 0)."""
    cfg = config.groups
    if cfg.leave_rate_hz <= 0 and cfg.merge_rate_hz <= 0:
        return
    dt = config.record_dt_s
    p_leave = step_probability(cfg.leave_rate_hz, dt)
    p_merge = step_probability(cfg.merge_rate_hz, dt)
    for label in np.unique(slots.label[slots.active]):
        u_leave, u_merge = rng.random(2)
        if int(label) in book.stops:  # stopping and standing groups meet and part in crowdsim.behaviours
            continue
        members = np.flatnonzero(slots.active & (slots.label == label))
        if len(members) == 0:
            continue
        if len(members) >= 2 and u_leave < p_leave:
            leave(slots, book, rng, config, scenario, int(rng.choice(members)))
        elif u_merge < p_merge:
            merge_nearest(slots, config, int(label))


def leave(slots: Slots, book: GroupBook, rng: np.random.Generator, config: SimConfig, scenario: Scenario,
          slot: int) -> None:
    """Pedestrian in `slot` leaves its group: a new singleton label, its own speed and destination."""
    slots.label[slot] = book.new_label()
    slots.speed[slot] = group_speed(rng, 1, config.social, config.groups)
    slots.goal[slot] = scenario.new_destination(rng, slots.pos[slot])


def merge_nearest(slots: Slots, config: SimConfig, label: int) -> bool:
    """Group `label` absorbs the nearest group walking the same way within merge_distance_m.

    The absorbed members take the label, destination and speed of `label`. Returns whether a merge
    happened.
    """
    s, cfg = slots, config.groups
    act = np.flatnonzero(s.active)
    mine = act[s.label[act] == label]
    others = act[s.label[act] != label]
    if len(others) == 0:
        return False
    centre = s.pos[mine].mean(axis=0)
    heading = s.goal[mine].mean(axis=0) - centre
    best, best_d = -1, cfg.merge_distance_m
    for other in np.unique(s.label[others]):
        members = others[s.label[others] == other]
        if len(members) + len(mine) > 2 * cfg.max_size:
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
    members = np.flatnonzero(s.active & (s.label == label))
    s.goal[members] = formation_goals(s.pos[members], destination, cfg.formation_spacing_m)
    return True
