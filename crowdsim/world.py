"""The physical world: the only module that imports pymunk.

Each pedestrian is a dynamic circle body (infinite moment, so it does not spin); walls and obstacles
are static segments on the space's static body. State moves in and out through pymunk's batch API,
so one call covers all bodies (FIELD_NOTES: body-by-body access costs ~100x more).
"""

from __future__ import annotations

import numpy as np
import pymunk
import pymunk.batch as batch

_PV = batch.BodyFields.POSITION | batch.BodyFields.VELOCITY
_VF = batch.BodyFields.VELOCITY | batch.BodyFields.FORCE


class PhysicsWorld:
    """Pedestrian bodies addressed by slot index, static walls given as segments (S, 2, 2) in metres.

    `collision_slop_m` is pymunk's allowed overlap before contacts push back; keep it at a few mm.
    """

    def __init__(self, segments: np.ndarray, wall_thickness_m: float = 0.02,
                 collision_slop_m: float = 0.002, iterations: int = 20) -> None:
        self.space = pymunk.Space()
        self.space.iterations = iterations
        self.space.collision_slop = collision_slop_m
        self.space.collision_bias = pow(1.0 - 0.3, 60.0)  # correct overlap faster than pymunk's default
        for a, b in np.asarray(segments, dtype=float).reshape(-1, 2, 2):
            seg = pymunk.Segment(self.space.static_body, tuple(a), tuple(b), wall_thickness_m)
            seg.friction = 0.0
            seg.elasticity = 0.0
            self.space.add(seg)
        self._bodies: dict[int, pymunk.Body] = {}
        self._slot_of_body: dict[int, int] = {}
        self._order: np.ndarray = np.empty(0, np.int64)
        self._is_ped: np.ndarray = np.empty(0, bool)
        self._ped_slots: np.ndarray = np.empty(0, np.int64)  # order[is_ped]: the slot of each pedestrian body
        self._dirty = False
        self._robot: pymunk.Body | None = None
        self._robot_radius = 0.0
        self._buf_get = batch.Buffer()
        self._buf_set = batch.Buffer()

    def __deepcopy__(self, memo: dict) -> PhysicsWorld:
        """An independent copy of the world in the same state (`pymunk.Space.copy`: bodies, shapes, their positions,
        velocities and forces). Its steps from here are the original's bit for bit, except where two bodies are in
        contact at the copy: pymunk does not copy its contact cache, so such contacts resolve a little differently
        (millimetres a step). `CrowdSimulator.fork` builds on it."""
        new = PhysicsWorld.__new__(PhysicsWorld)
        memo[id(self)] = new
        new.space = self.space.copy()
        twin = {id(old): body for old, body in zip(self.space.bodies, new.space.bodies, strict=True)}
        new._bodies = {slot: twin[id(body)] for slot, body in self._bodies.items()}
        new._slot_of_body = {body.id: slot for slot, body in new._bodies.items()}
        new._robot = None if self._robot is None else twin[id(self._robot)]
        new._robot_radius = self._robot_radius
        new._order, new._is_ped, new._ped_slots = np.empty(0, np.int64), np.empty(0, bool), np.empty(0, np.int64)
        new._dirty = True  # the copies have new body ids: the batch order is looked up again
        new._buf_get, new._buf_set = batch.Buffer(), batch.Buffer()
        if hasattr(self, "_force_packed"):
            new._force_packed = self._force_packed.copy()
        return new

    def add(self, slot: int, pos: np.ndarray, vel: np.ndarray, radius_m: float, mass_kg: float) -> None:
        """Add the pedestrian body of `slot` at pos (2,) m with velocity vel (2,) m/s."""
        if slot in self._bodies:
            raise ValueError(f"slot {slot} already has a body")
        body = pymunk.Body(mass_kg, float("inf"))
        body.position = (float(pos[0]), float(pos[1]))
        body.velocity = (float(vel[0]), float(vel[1]))
        shape = pymunk.Circle(body, float(radius_m))
        shape.friction = 0.0
        shape.elasticity = 0.0
        self.space.add(body, shape)
        self._bodies[slot] = body
        self._slot_of_body[body.id] = slot
        self._dirty = True

    def remove(self, slot: int) -> None:
        body = self._bodies.pop(slot)
        del self._slot_of_body[body.id]
        self.space.remove(body, *body.shapes)
        self._dirty = True

    def place_robot(self, pos: np.ndarray, vel: np.ndarray, radius_m: float) -> None:
        """Put the robot's kinematic disc at pos (2,) moving at vel (2,): pedestrians cannot pass through
        it, and it is not pushed back. Called again, it moves the same body."""
        if self._robot is None or self._robot_radius != radius_m:
            self.remove_robot()
            body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            shape = pymunk.Circle(body, float(radius_m))
            shape.friction = 0.0
            self.space.add(body, shape)
            self._robot, self._robot_radius = body, radius_m
            self._dirty = True
        self._robot.position = (float(pos[0]), float(pos[1]))
        self._robot.velocity = (float(vel[0]), float(vel[1]))

    def robot_position(self) -> np.ndarray | None:
        return None if self._robot is None else np.array(self._robot.position)

    def remove_robot(self) -> None:
        if self._robot is not None:
            self.space.remove(self._robot, *self._robot.shapes)
            self._robot = None
            self._dirty = True

    def teleport(self, slot: int, pos: np.ndarray) -> None:
        """Move a body without dynamics (used by periodic scenarios)."""
        self._bodies[slot].position = (float(pos[0]), float(pos[1]))

    def _body_order(self) -> np.ndarray:
        """Slots in pymunk's iteration order (it changes whenever a body is removed); -1 marks the
        static body that carries the walls, which the batch API also visits."""
        if self._dirty:
            buf = batch.Buffer()
            batch.get_space_bodies(self.space, batch.BodyFields.BODY_ID, buf)
            ids = np.frombuffer(buf.int_buf(), dtype=np.uint64)
            self._order = np.full(len(ids), -1, np.int64)  # the slot of each body (-1: the static body, the robot)
            if self._slot_of_body:  # look every id up at once among the pedestrians' (sorted) body ids
                known = np.fromiter(self._slot_of_body.keys(), np.uint64, len(self._slot_of_body))
                slots = np.fromiter(self._slot_of_body.values(), np.int64, len(self._slot_of_body))
                by_id = np.argsort(known)
                known, slots = known[by_id], slots[by_id]
                at = np.minimum(np.searchsorted(known, ids), len(known) - 1)
                found = known[at] == ids
                self._order[found] = slots[at[found]]
            self._is_ped = self._order >= 0
            self._ped_slots = self._order[self._is_ped]
            self._dirty = False
        return self._order

    def read(self, pos_out: np.ndarray, vel_out: np.ndarray) -> None:
        """Write every body's position and velocity into rows `slot` of pos_out / vel_out (C, 2)."""
        order = self._body_order()
        if len(order) == 0:
            return
        self._buf_get.clear()
        batch.get_space_bodies(self.space, _PV, self._buf_get)
        data = np.frombuffer(self._buf_get.float_buf(), dtype=np.float64).reshape(-1, 4)[self._is_ped]
        pos_out[self._ped_slots] = data[:, 0:2]
        vel_out[self._ped_slots] = data[:, 2:4]

    def write(self, vel: np.ndarray, force: np.ndarray) -> None:
        """Set velocity (C, 2) m/s and force (C, 2) N of every body from rows `slot`."""
        order = self._body_order()
        if len(order) == 0:
            return
        rows = np.zeros((len(order), 4))  # per body: velocity, force; zeros for non-pedestrian bodies
        rows[self._is_ped, 0:2] = vel[self._ped_slots]
        rows[self._is_ped, 2:4] = force[self._ped_slots]
        self._force_packed = np.ascontiguousarray(rows[:, 2:4]).ravel()
        packed = rows.ravel()
        self._packed = packed  # keep the memory alive while pymunk reads it
        self._buf_set.set_float_buf(packed)
        robot_vel = None if self._robot is None else self._robot.velocity
        batch.set_space_bodies(self.space, _VF, self._buf_set)
        if robot_vel is not None:  # the batch write zeroed it with the other non-pedestrian bodies
            self._robot.velocity = robot_vel

    def repeat_force(self) -> None:
        """Apply the force of the last `write` again (pymunk clears forces after every sub-step)."""
        if len(self._order) == 0:
            return
        self._buf_set.set_float_buf(self._force_packed)
        batch.set_space_bodies(self.space, batch.BodyFields.FORCE, self._buf_set)

    def step(self, dt_s: float) -> None:
        self.space.step(dt_s)

    @property
    def n_bodies(self) -> int:
        return len(self._bodies)
