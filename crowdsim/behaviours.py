"""Behaviours beyond walking in formation: stopping to stand in an F-formation, meeting and parting at a
stop, and strangers who enter close together (parameters and sources: `BehaviourConfig`).

A stopped group is recorded in the group book (`GroupBook.stops`, by label). While it walks to its stop and
stands there its members' goals are their places on the F-formation circle, so the driving force brings them
to rest there; they are never taken for arrivals at an exit. The functions change the simulator's slots and
book and never see the simulator itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crowdsim.config import SimConfig
from crowdsim.groups import GroupBook, formation_goals, placement_ok, step_probability
from crowdsim.scenarios import Scenario
from crowdsim.state import Slots

APPROACH_LIMIT_S = 30.0  # a group that has not reached its places by then starts its stop where it is


@dataclass
class Stop:
    """A group's stop: o-space centre (2,) m, the destination (2,) m to walk on to afterwards, the standing
    time s, and since_s: when the group chose the stop, then (once `standing`) when it began to stand."""

    centre: np.ndarray
    destination: np.ndarray
    duration_s: float
    since_s: float
    standing: bool = False


def fformation(n: int, centre: np.ndarray, spacing_m: float, phase: float) -> np.ndarray:
    """(n, 2) places of n people on a circle around centre (2,), neighbours spacing_m apart centre to centre
    (a pair stands face to face, spacing_m apart; one person stands on the centre), rotated by phase rad."""
    if n == 1:
        return centre[None].copy()
    radius = spacing_m / 2.0 if n == 2 else spacing_m / (2.0 * np.sin(np.pi / n))
    angles = phase + 2.0 * np.pi * np.arange(n) / n
    return centre + radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)


def assign_places(positions: np.ndarray, places: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """places (n, 2) reordered so that member k gets the place at its own bearing from centre (the circle
    keeps the members' order, rotated to fit them best)."""
    n = len(positions)
    order = np.argsort(np.arctan2(*(positions - centre).T[::-1]), kind="stable")
    best, best_cost = places, np.inf
    for shift in range(n):
        cand = np.empty_like(places)
        cand[order] = np.roll(places, shift, axis=0)
        cost = float(np.sum((cand - positions) ** 2))
        if cost < best_cost:
            best, best_cost = cand, cost
    return best


def stopped(book: GroupBook, labels: np.ndarray) -> np.ndarray:
    """(n,) bool: which of these labels belong to a group that is stopping or standing."""
    return np.isin(labels, np.fromiter(book.stops, dtype=np.int64, count=len(book.stops)))


def update(slots: Slots, book: GroupBook, rng: np.random.Generator, config: SimConfig, scenario: Scenario,
           time_s: float) -> None:
    """One recording step of behaviours: strangers keep pace, end stops that are over, part and join at stops,
    start new stops."""
    cfg = config.behaviour
    if book.following:
        keep_pace(slots, book, config)
    for label in list(book.stops):
        _advance_stop(slots, book, config, int(label), time_s)
    if cfg.part_rate_hz > 0 or cfg.join_rate_hz > 0:
        for label in [lb for lb, st in book.stops.items() if st.standing]:
            _meet_and_part(slots, book, rng, config, scenario, int(label), time_s)
    if cfg.stop_rate_hz > 0 and (scenario.stop_areas or scenario.pois):
        p_stop = step_probability(cfg.stop_rate_hz, config.record_dt_s)
        act = np.flatnonzero(slots.active)
        for label in np.unique(slots.label[act]):
            if int(label) not in book.stops and rng.random() < p_stop:
                _start_stop(slots, book, rng, config, scenario, int(label), time_s)


def _members(slots: Slots, label: int) -> np.ndarray:
    return np.flatnonzero(slots.active & (slots.label == label))


FOLLOW_LOST_M = 3.0  # a stranger whose along-track gap changed by more than this has lost the group


def keep_pace(slots: Slots, book: GroupBook, config: SimConfig) -> None:
    """Strangers who entered beside a group keep pace with it (`BehaviourConfig.stranger_follow_gain_per_s`): the
    desired speed (m/s) of each one in `book.following` becomes the group's walking speed plus gain x (gap at
    entry - gap now), the gap being its along-track offset from the group's centre (m), clipped to the desired
    speed range. It lets go when either has left, the group stops, or the gap has changed by over FOLLOW_LOST_M."""
    gain, social = config.behaviour.stranger_follow_gain_per_s, config.social
    for label, (leader, gap0) in list(book.following.items()):
        me, them = _members(slots, label), _members(slots, leader)
        if gain == 0 or len(me) != 1 or len(them) == 0 or leader in book.stops or label in book.stops:
            del book.following[label]
            continue
        v = slots.vel[them].mean(axis=0)
        speed = float(np.hypot(*v))
        if speed < 0.2:  # the group is (nearly) standing: no walking direction to keep pace along
            continue
        gap = float((slots.pos[me[0]] - slots.pos[them].mean(axis=0)) @ (v / speed))
        if abs(gap - gap0) > FOLLOW_LOST_M:
            del book.following[label]
            continue
        slots.speed[me[0]] = float(np.clip(speed + gain * (gap0 - gap), social.desired_speed_min_mps,
                                           social.desired_speed_max_mps))


def _start_stop(slots: Slots, book: GroupBook, rng: np.random.Generator, config: SimConfig,
                scenario: Scenario, label: int, time_s: float) -> None:
    cfg = config.behaviour
    members = _members(slots, label)
    if scenario.pois and (not scenario.stop_areas or rng.random() < cfg.poi_share):
        centre = np.asarray(scenario.pois[int(rng.integers(len(scenario.pois)))], float) + rng.normal(0, 0.7, 2)
    else:
        area = scenario.stop_areas[int(rng.integers(len(scenario.stop_areas)))]
        centre = np.array([rng.uniform(area[0], area[2]), rng.uniform(area[1], area[3])])
    places = fformation(len(members), centre, cfg.fformation_spacing_m, rng.uniform(0.0, 2.0 * np.pi))
    # the spot must be clear of walls and of the places of every other stop
    taken = [fformation(len(_members(slots, lb)), st.centre, cfg.fformation_spacing_m, 0.0)
             for lb, st in book.stops.items()]
    others = np.concatenate(taken) if taken else np.zeros((0, 2))
    if not placement_ok(places, slots.radius[members] + 0.1, others, np.full(len(others), 0.7), scenario.walls):
        return
    duration = max(cfg.stop_min_s, float(rng.exponential(cfg.stop_mean_s)))
    destination = slots.goal[members].mean(axis=0)
    book.stops[label] = Stop(centre, destination, duration, time_s)
    slots.goal[members] = assign_places(slots.pos[members], places, centre)


def _advance_stop(slots: Slots, book: GroupBook, config: SimConfig, label: int, time_s: float) -> None:
    """Start standing once every member is at its place (or the approach took too long); end the stop when
    its time is up, sending the group on to its destination in formation."""
    stop = book.stops[label]
    members = _members(slots, label)
    if len(members) == 0:
        del book.stops[label]
        return
    if not stop.standing:
        there = np.all(np.linalg.norm(slots.pos[members] - slots.goal[members], axis=1) < 0.4)
        if there or time_s - stop.since_s > APPROACH_LIMIT_S:
            stop.standing, stop.since_s = True, time_s
        return
    if time_s - stop.since_s >= stop.duration_s:
        del book.stops[label]
        slots.goal[members] = formation_goals(slots.pos[members], stop.destination,
                                              config.groups.formation_spacing_m)


def _regroup(slots: Slots, config: SimConfig, stop: Stop, members: np.ndarray, rng: np.random.Generator) -> None:
    """Lay the F-formation out again for the current members (someone joined or left)."""
    places = fformation(len(members), stop.centre, config.behaviour.fformation_spacing_m,
                        rng.uniform(0.0, 2.0 * np.pi))
    slots.goal[members] = assign_places(slots.pos[members], places, stop.centre)


def _meet_and_part(slots: Slots, book: GroupBook, rng: np.random.Generator, config: SimConfig,
                   scenario: Scenario, label: int, time_s: float) -> None:
    cfg, stop, dt = config.behaviour, book.stops[label], config.record_dt_s
    members = _members(slots, label)
    p_part = step_probability(cfg.part_rate_hz, dt)
    if len(members) >= 2 and rng.random() < 1.0 - (1.0 - p_part) ** len(members):
        slot = int(rng.choice(members))
        slots.label[slot] = book.new_label()
        book.enter(int(slots.label[slot]), 1, time_s)
        slots.goal[slot] = scenario.new_destination(rng, slots.pos[slot])
        _regroup(slots, config, stop, members[members != slot], rng)
        return
    p_join = step_probability(cfg.join_rate_hz, dt)
    if len(members) >= config.groups.max_size or rng.random() >= p_join:
        return
    act = np.flatnonzero(slots.active)
    labels, counts = np.unique(slots.label[act], return_counts=True)
    singles = act[np.isin(slots.label[act], labels[counts == 1]) & ~stopped(book, slots.label[act])]
    near = singles[np.linalg.norm(slots.pos[singles] - stop.centre, axis=1) < cfg.join_distance_m]
    if len(near) == 0:
        return
    newcomer = int(near[np.argmin(np.linalg.norm(slots.pos[near] - stop.centre, axis=1))])
    book.entered.pop(int(slots.label[newcomer]), None)  # its own label is gone for good
    slots.label[newcomer] = label
    slots.speed[newcomer] = slots.speed[members].mean()
    _regroup(slots, config, stop, np.append(members, newcomer), rng)


def stranger_spot(slots: Slots, members: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray,
                                                                                       float]:
    """Where a stranger enters next to the group in slots `members` (just entered): one step behind it
    (0.9–1.4 m behind its rearmost member) or beside it (0.8–1.1 m beyond its outermost member), with a
    destination near the group's and a desired speed within a few cm/s of the group's. Returns position (2,) m,
    goal (2,) m and desired speed m/s; the caller checks that the spot is clear."""
    pos, goal = slots.pos[members], slots.goal[members]
    centre, destination = pos.mean(axis=0), goal.mean(axis=0)
    heading = (destination - centre) / max(float(np.linalg.norm(destination - centre)), 1e-9)
    side = np.array([-heading[1], heading[0]])
    if rng.random() < 0.5:
        spot = centre + heading * (float(np.min((pos - centre) @ heading)) - rng.uniform(0.9, 1.4))
    else:
        sign = 1.0 if rng.random() < 0.5 else -1.0
        spot = centre + sign * side * (float(np.max(sign * (pos - centre) @ side)) + rng.uniform(0.8, 1.1))
    target = destination + side * rng.normal(0.0, 0.5)
    speed = float(slots.speed[members].mean() + rng.normal(0.0, 0.03))
    return spot, target, speed
