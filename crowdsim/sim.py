"""The crowd simulator: social forces on pymunk bodies, groups with ground-truth labels, a robot slot.

`CrowdSimulator(config).reset(seed)` builds a crowd; each `step()` advances one recording step
(`record_dt_s`, 0.4 s by default): social forces are recomputed every `force_dt_s` and pymunk resolves
contacts in sub-steps of at most 0.05 s. All randomness comes from the Generator made in `reset`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from crowdsim import behaviours, detour, forces, kernels
from crowdsim.config import SimConfig
from crowdsim.events import apply_events
from crowdsim.groups import (
    GroupBook,
    draw_group_sizes,
    draw_inflow_size,
    formation_goals,
    formation_offsets,
    group_speed,
    hex_lattice,
    placement_ok,
    rotate_to,
)
from crowdsim.neighbors import neighbor_pairs
from crowdsim.scenarios import Scenario, make_scenario
from crowdsim.state import CrowdState, Slots
from crowdsim.world import PhysicsWorld


@dataclass
class Robot:
    pos: np.ndarray  # (2,) m
    vel: np.ndarray  # (2,) m/s
    radius_m: float


class CrowdSimulator:
    """One crowd in one scenario. See the module docstring for the step structure."""

    def __init__(self, config: SimConfig | None = None, scenario: Scenario | None = None) -> None:
        self.config = config or SimConfig()
        self.scenario = scenario or make_scenario(self.config.scenario, dict(self.config.scenario_options))
        self.rng = np.random.default_rng(0)
        self.robot: Robot | None = None
        self._params = kernels.pack_params(self.config.social, self.config.group_forces)
        self._corners = detour.Corners.of(self.scenario.walls, self.config.social.detour_clearance_m)
        self._reset_storage()

    # ----------------------------------------------------------------------------------------- setup
    def _reset_storage(self) -> None:
        self.slots = Slots.empty(self.config.n_pedestrians)
        self.world = PhysicsWorld(self.scenario.walls)
        self.frame = 0
        self.time_s = 0.0
        self._next_ped_id = 1
        self.book = GroupBook(self.config.groups.max_size)
        self.n_spawned = 0
        self.n_exited = 0
        self._index_cache: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        # (active slots, their labels, dense labels, whether a group is larger than 3): reused while unchanged
        self._label_cache: tuple[np.ndarray, np.ndarray, np.ndarray, bool] | None = None
        self._synced = False  # slots.pos / vel hold what the world would read (no physics step since the read)

    def reset(self, seed: int | None = None) -> CrowdState:
        """Start a new crowd. The same seed and config give the same run, bit for bit."""
        self.rng = np.random.default_rng(seed)
        self._reset_storage()
        self.robot = None
        self.world.remove_robot()
        if self.scenario.dense_spawn is not None:
            self._spawn_dense()
        else:
            self._spawn_initial()
        return self.state()

    def _spawn_initial(self) -> None:
        cfg = self.config
        # groups of exit scenarios start part-way along their route; others start at their origin
        progress_max = 0.8 if self.scenario.on_arrival == "remove" and self.scenario.periodic_x is None else 0.0
        for size in draw_group_sizes(self.rng, cfg.n_pedestrians, cfg.groups):
            if not self._try_spawn_group(size, progress_max, tries=200):
                raise RuntimeError(
                    f"could not place a group of {size} in scenario {self.scenario.name!r} with "
                    f"{cfg.n_pedestrians} pedestrians: the scene is too small for this crowd"
                )

    def _spawn_dense(self) -> None:
        density = float(self.scenario.options.get("density", 0.0))
        sites = hex_lattice(self.scenario.dense_spawn, density)
        n = self.config.n_pedestrians
        if len(sites) < n:
            raise ValueError(f"the dense spawn area holds {len(sites)} sites at {density}/m^2, fewer than {n}")
        if self.scenario.periodic_x is not None:  # fill the ring uniformly
            sites = sites[np.sort(self.rng.choice(len(sites), n, replace=False))]
        else:  # fill from the exit backwards
            door = np.array([self.scenario.bounds[2], 0.5 * (self.scenario.bounds[1] + self.scenario.bounds[3])])
            sites = sites[np.argsort(np.linalg.norm(sites - door, axis=1), kind="stable")[:n]]
        start = 0
        for size in draw_group_sizes(self.rng, n, self.config.groups):
            _, target = self.scenario.draw_flow(self.rng)
            pos = sites[start:start + size] + self.rng.normal(0.0, 0.005, (size, 2))
            self._add_group(pos, np.repeat(target[None], size, 0), self._radii(size))
            start += size

    def _radii(self, size: int) -> np.ndarray:
        return self.rng.uniform(self.config.radius_min_m, self.config.radius_max_m, size)

    def _try_spawn_group(self, size: int, progress_max: float, tries: int) -> bool:
        """Place a group in formation at a random flow origin; False if no clear spot was found."""
        s = self.slots
        act = s.active
        for _ in range(tries):
            origin, target = self.scenario.draw_flow(self.rng)
            if progress_max > 0 and self.scenario.interior is not None:
                lo, hi = np.array(self.scenario.interior[:2]), np.array(self.scenario.interior[2:])
                origin = lo + self.rng.uniform(0.0, 1.0, 2) * (hi - lo)
            elif progress_max > 0:
                origin = origin + self.rng.uniform(0.0, progress_max) * (target - origin)
            direction = target - origin
            local = formation_offsets(size, self.config.groups.formation_spacing_m * self._spacing_factor(size))
            offsets = rotate_to(local - local.mean(axis=0), direction)
            radius = self._radii(size)
            pos = origin + offsets
            # every member on the origin's side of the walls (a disc beyond a wall also "clears" it)
            inside = not forces.crossed_walls(np.repeat(origin[None], size, axis=0), pos, self.scenario.walls).any()
            if inside and placement_ok(pos, radius, *self._occupied(act), self.scenario.walls):
                lateral = rotate_to(local * np.array([0.0, 1.0]), direction)
                self._add_group(pos, target + lateral, radius)
                return True
        return False

    def _occupied(self, act: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Discs a new group must clear: positions (m, 2) and radii (m,) of the active pedestrians and of a
        visible robot (an invisible one changes nothing in the crowd, so people may appear on it)."""
        pos, radius = self.slots.pos[act], self.slots.radius[act]
        if self.robot is None or not self.config.robot.visible:
            return pos, radius
        return np.vstack([pos, self.robot.pos[None]]), np.append(radius, self.robot.radius_m)

    def _spacing_factor(self, size: int) -> float:
        """This group's scale of the formation spacing: 1 + N(0, member_spacing_std), within [0.6, 1.4]."""
        std = self.config.behaviour.member_spacing_std
        return float(np.clip(1.0 + self.rng.normal(0.0, std), 0.6, 1.4)) if size > 1 and std > 0 else 1.0

    def _member_speeds(self, size: int, speed: float) -> np.ndarray:
        """(size,) desired speeds, m/s: the group's plus N(0, member_speed_std_mps) each, clipped."""
        std, social = self.config.behaviour.member_speed_std_mps, self.config.social
        if size == 1 or std == 0:
            return np.full(size, speed)
        return np.clip(speed + self.rng.normal(0.0, std, size), social.desired_speed_min_mps,
                       social.desired_speed_max_mps)

    def _add_group(self, pos: np.ndarray, goals: np.ndarray, radius: np.ndarray,
                   speed: float | None = None) -> int:
        """Activate a new group at pos (n, 2) with goals (n, 2) and radii (n,); returns its label."""
        size = len(pos)
        free = np.flatnonzero(~self.slots.active)
        if len(free) < size:
            raise RuntimeError("no free pedestrian slots")
        label = self.book.new_label()
        self.book.enter(label, size, self.time_s)
        if speed is None:
            speed = group_speed(self.rng, size, self.config.social, self.config.groups)
        speeds = self._member_speeds(size, speed)
        for k, slot in enumerate(free[:size]):
            self.slots.activate(slot, self._next_ped_id, label, pos[k], goals[k], radius[k], speeds[k])
            self.world.add(int(slot), pos[k], np.zeros(2), radius[k], self.config.mass_kg)
            self._next_ped_id += 1
        self._index_cache = None
        self.n_spawned += size
        self.book.last_spawned = label
        return label

    # ------------------------------------------------------------------------------------------ robot
    def set_robot(self, pos: np.ndarray, vel: np.ndarray, radius_m: float | None = None) -> None:
        """Place the external agent for the next step: pos (2,) m, vel (2,) m/s, radius m."""
        pos = np.asarray(pos, dtype=float)
        vel = np.asarray(vel, dtype=float)
        radius = self.config.robot.radius_m if radius_m is None else float(radius_m)
        if pos.shape != (2,) or vel.shape != (2,):
            raise ValueError(f"robot pos and vel must have shape (2,), got {pos.shape} and {vel.shape}")
        if not all(map(math.isfinite, (float(pos[0]), float(pos[1]), float(vel[0]), float(vel[1]), radius))) \
                or radius <= 0:
            raise ValueError(f"robot state must be finite with a positive radius: pos={pos}, vel={vel}, "
                             f"radius={radius}")
        self.robot = Robot(pos.copy(), vel.copy(), radius)
        if self.config.robot.visible:
            self.world.place_robot(pos, vel, radius)

    def clear_robot(self) -> None:
        self.robot = None
        self.world.remove_robot()

    # ------------------------------------------------------------------------------------------- step
    def step(self) -> CrowdState:
        """Advance one recording step and return the new state."""
        for _ in range(self.config.force_steps_per_record):
            self._force_step()
        self.world.read(self.slots.pos, self.slots.vel)
        self._synced = True
        self._wrap_periodic()
        self._arrivals()
        apply_events(self.slots, self.book, self.rng, self.config, self.scenario)
        behaviours.update(self.slots, self.book, self.rng, self.config, self.scenario, self.time_s)
        if self.scenario.continuous:
            self._inflow()
        self._index_cache = None
        self.frame += 1
        self.time_s = self.frame * self.config.record_dt_s
        return self.state()

    def accelerations(self, reference: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Social accelerations (n_active, 2) m/s^2 and the active slot indices (n_active,).

        reference=True evaluates the numpy functions of `crowdsim.forces` instead of the compiled kernel
        (same formulas; used by tests). Fluctuations are added by the caller.
        """
        s, cfg = self.slots, self.config
        idx, labels, gaze = self._active_index()
        pos, vel = s.pos[idx], s.vel[idx]
        aim = (detour if reference else kernels).aims(pos, s.goal[idx], self._corners, cfg.social.slowdown_radius_m)
        if reference:
            v_des = forces.desired_velocity(pos, aim, s.speed[idx], cfg.social)
            e = forces.headings(vel, v_des)
        else:
            v_des, e = kernels.desired_and_heading(pos, vel, aim, s.speed[idx], cfg.social.slowdown_radius_m)
        radius = s.radius[idx]
        pos_all, rad_all, e_all, lab_all = pos, radius, e, labels
        if self.robot is not None and cfg.robot.visible:
            e_r = self._robot_heading()
            pos_all = np.concatenate([pos, self.world.robot_position()[None]])
            rad_all, e_all = np.append(radius, self.robot.radius_m), np.concatenate([e, e_r])
            lab_all = np.append(labels, -1)  # the robot is in no group
        pos_all, rad_all, e_all, lab_all = self._periodic_ghosts(pos_all, rad_all, e_all, lab_all)
        i, j = neighbor_pairs(pos_all, cfg.social.cutoff_m)
        if not reference:
            acc = kernels.social_acc(pos_all, rad_all, e_all, i, j, len(idx), vel, v_des, self.scenario.walls,
                                     labels, gaze, self._params, lab_all)
            return acc, idx
        acc = forces.pedestrian_acc(pos_all, rad_all, e_all, i, j, cfg.social, lab_all,
                                    cfg.group_forces.member_ped_repulsion_scale)[: len(idx)]
        acc += forces.driving_acc(vel, v_des, cfg.social)
        acc += forces.wall_acc(pos, radius, self.scenario.walls, cfg.social)
        inner = (i < len(idx)) & (j < len(idx))
        acc += forces.group_acc(pos, vel, e, labels, i[inner], j[inner], cfg.group_forces, gaze, v_des)
        return acc, idx

    def _robot_heading(self) -> np.ndarray:
        """(1, 2) `forces.unit` of the robot's velocity (the same float operations, without array overhead)."""
        vx, vy = float(self.robot.vel[0]), float(self.robot.vel[1])
        norm = math.sqrt(vx * vx + vy * vy)
        moving = norm > forces._EPS
        safe = norm if moving else 1.0
        return np.array([[vx / safe * float(moving), vy / safe * float(moving)]])

    def _active_index(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Active slots (n,), their dense group labels (n,) and gaze sub-group labels (n,); cached while
        membership is unchanged (it only changes between recording steps: spawns, exits and group events)."""
        if self._index_cache is None:
            s = self.slots
            idx = np.flatnonzero(s.active)
            labels, prev = s.label[idx], self._label_cache
            if prev is not None and np.array_equal(prev[0], idx) and np.array_equal(prev[1], labels):
                dense, big = prev[2], prev[3]
            else:
                dense = s.dense_labels(idx)
                big = bool(len(dense)) and int(np.bincount(dense).max()) > 3
                self._label_cache = (idx, labels, dense, big)
            # with no group above 3 every group is one sub-group: gaze_subgroups would return `dense` itself
            gaze = kernels.gaze_subgroups(s.pos[idx], s.goal[idx], dense) if big else dense
            self._index_cache = (idx, dense, gaze)
        return self._index_cache

    def _periodic_ghosts(self, pos: np.ndarray, radius: np.ndarray, e: np.ndarray,
                         label: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Append shifted copies of agents within the cut-off of a periodic seam, so that interactions
        reach across it. Real agents keep their row indices; ghosts come after them, with their source's
        group label."""
        if self.scenario.periodic_x is None:
            return pos, radius, e, label
        x0, x1 = self.scenario.periodic_x
        cut = self.config.social.cutoff_m
        near_lo = np.flatnonzero(pos[:, 0] < x0 + cut)
        near_hi = np.flatnonzero(pos[:, 0] > x1 - cut)
        ghosts = np.concatenate([pos[near_lo] + [x1 - x0, 0.0], pos[near_hi] - [x1 - x0, 0.0]])
        src = np.concatenate([near_lo, near_hi])
        return (np.concatenate([pos, ghosts]), np.append(radius, radius[src]), np.concatenate([e, e[src]]),
                np.append(label, label[src]))

    def _force_step(self) -> None:
        s, cfg = self.slots, self.config
        if not self._synced:  # right after a step's final read the world holds exactly slots.pos / vel
            self.world.read(s.pos, s.vel)
        if not s.active.any():
            return
        self._ring_goals()
        acc, idx = self.accelerations()
        if cfg.social.fluctuation_mps2 > 0:
            acc += self.rng.normal(0.0, cfg.social.fluctuation_mps2, acc.shape)
        force = np.zeros_like(s.pos)
        force[idx] = acc * cfg.mass_kg
        kernels.cap_speed_rows(s.vel, idx, s.speed, cfg.social.max_speed_factor)  # = forces.cap_speed on rows idx
        self.world.write(s.vel, force)
        for k in range(cfg.physics_substeps):
            if k:
                self.world.repeat_force()
            self.world.step(cfg.physics_dt_s)
        self._synced = False

    def _ring_goals(self) -> None:
        """On a periodic ring every goal stays 5 m ahead of its pedestrian, so nobody ever arrives."""
        if self.scenario.periodic_x is not None:
            act = self.slots.active
            self.slots.goal[act, 0] = self.slots.pos[act, 0] + 5.0

    def _wrap_periodic(self) -> None:
        if self.scenario.periodic_x is None:
            return
        x0, x1 = self.scenario.periodic_x
        for slot in np.flatnonzero(self.slots.active & (self.slots.pos[:, 0] > x1)):
            self.slots.pos[slot, 0] -= x1 - x0
            self.world.teleport(int(slot), self.slots.pos[slot])

    def _arrivals(self) -> None:
        s, scen = self.slots, self.scenario
        idx = np.flatnonzero(s.active)
        if self.book.stops:  # a group on its way to a stop, or standing, has not arrived anywhere
            idx = idx[~behaviours.stopped(self.book, s.label[idx])]
        if not kernels.any_within(s.pos, s.goal, idx, scen.exit_radius_m):  # nobody arrived: nothing below acts
            return
        d = s.pos[idx] - s.goal[idx]
        dist = np.sqrt(np.einsum("ij,ij->i", d, d))  # = np.linalg.norm(d, axis=1), bit for bit
        if scen.on_arrival == "remove":
            # a group leaves together: with one member out, those within 2 m of their own exit follow at once
            # (a remnant would otherwise count as a smaller group for a second or two)
            gone = np.isin(s.label[idx], s.label[idx[dist < scen.exit_radius_m]]) & (dist < scen.exit_radius_m + 2.0)
            for slot in idx[(dist < scen.exit_radius_m) | gone]:
                label = int(s.label[slot])
                self.world.remove(int(slot))
                s.deactivate(slot)
                self.n_exited += 1
                if not np.any(s.active & (s.label == label)):
                    self.book.left(label, self.time_s)
        elif scen.on_arrival == "new_goal":
            for label in np.unique(s.label[idx[dist < scen.exit_radius_m]]):
                self.retarget_group(int(label))

    def retarget_group(self, label: int, destination: np.ndarray | None = None) -> None:
        """Give every member of group `label` a new shared destination (in formation)."""
        s = self.slots
        members = np.flatnonzero(s.active & (s.label == label))
        if destination is None:
            destination = self.scenario.new_destination(self.rng, s.pos[members].mean(axis=0))
        s.goal[members] = formation_goals(s.pos[members], destination, self.config.groups.formation_spacing_m)

    def _inflow(self) -> None:
        """Keep the crowd size with whole groups drawn from the configured size distribution.

        The next group's size is drawn once (`draw_inflow_size`: the configured distribution, corrected for
        how long each size stays, so that the people in the scene keep the composition it implies), and the
        group waits, however many steps it takes, until the scene has free slots for all of it and a clear
        spot at an entrance. Filling the gaps with whatever fits would bias arrivals towards singles (people
        leave one by one), and the share in groups would decay.
        """
        if self.book.pending_size == 0:
            self.book.pending_size = draw_inflow_size(self.rng, self.config.groups, self.book.mean_stay_s(),
                                                      self.config.n_pedestrians)
        if int((~self.slots.active).sum()) < self.book.pending_size:
            return
        if self.book.pending_size == 1 and self._try_spawn_stranger():
            self.book.pending_size = 0
        elif self._try_spawn_group(self.book.pending_size, 0.0, tries=3):
            self.book.pending_size = 0

    def _try_spawn_stranger(self) -> bool:
        """With probability `stranger_companion_prob`, the arriving single enters beside or behind the group
        that entered last (if that was under 5 s ago): a stranger walking close (`behaviours.stranger_spot`)."""
        p = self.config.behaviour.stranger_companion_prob
        last = self.book.last_spawned
        if p == 0 or self.rng.random() >= p or last not in self.book.entered or last in self.book.stops:
            return False
        members = np.flatnonzero(self.slots.active & (self.slots.label == last))
        if len(members) == 0 or self.time_s - self.book.entered[last][0] > 5.0:
            return False
        spot, target, speed = behaviours.stranger_spot(self.slots, members, self.rng)
        radius = self._radii(1)
        centre = self.slots.pos[members].mean(axis=0)
        if forces.crossed_walls(centre[None], spot[None], self.scenario.walls).any() or not placement_ok(
                spot[None], radius, *self._occupied(self.slots.active), self.scenario.walls):
            return False
        label = self._add_group(spot[None], target[None], radius, speed)
        heading = (target - centre) / max(float(np.linalg.norm(target - centre)), 1e-9)
        self.book.following[label] = (int(last), float((spot - centre) @ heading))  # `behaviours.keep_pace`
        return True

    # ------------------------------------------------------------------------------------------ state
    def state(self) -> CrowdState:
        """A copy of the current state (capacity-sized arrays with an active mask)."""
        return self.slots.snapshot(self.frame, self.time_s, self._active_index()[1])
