"""The MPC's nonlinear program, built once with CasADi and solved with IPOPT or fatrop.

Decision variables are stage-ordered for fatrop:
``z0 u0 s0 | z1 u1 s1 | ... | z_{H-1} u_{H-1} s_{H-1} | z_H s_H``, with z the robot state, u the control
and s the slacks of that stage (one shared by the pedestrians, one by the group slots, one by the walls).
Constraints are ordered ``dyn_0 path_0 dyn_1 path_1 ... path_H`` with
``dyn_k = z_{k+1} - f(z_k, u_k, dt)``, and every path constraint is local to its stage.

Cost (summed over stages; positions p_k = z_k[:2], stages 1..H unless noted):

* progress: ``goal * hub(p_k - goal)`` plus ``goal_terminal * hub(p_H - goal)``, with the pseudo-Huber
  distance ``hub(d) = sqrt(|d|² + 0.01) - 0.1`` (m);
* effort (k = 0..H-1): ``effort * sum((u_k / u_max)²)``;
* smoothness (k = 0..H-1): ``smoothness * sum(((u_k - v_k) / (a_max dt))²)``, v_k the velocity in z_k;
* social comfort: ``social / K * sum_{m, j} mask_m exp(-|p_k - q_kmj|² / (2 comfort²))``;
* slacks: ``slack_l1 * s + slack_l2 * s²``.

Soft constraints, all in metres (d = sqrt(|.|² + 1e-6)), at every knot p_k and, with
``check_midpoints`` (off by default: it doubles the constraints), also half-way through each step at
f(z_k, u_k, dt/2), which stays local to stage k and catches fast head-on passes between knots:

* pedestrian m, mode j: ``mask_m (d(p, q_mj(t)) - clear_m(t)) + s_km >= 0`` (clear_m(t) may grow with t); with
  guidance (``MPCConfig.guidance``) a switch per pedestrian turns it into the half-plane
  ``mask_m (n_mj(t) . (p - q_mj(t)) - clear_m(t)) + s_km >= 0`` (planner/guidance.py);
* group g, mode j: ``mask_g (d(p, capsule segment_gj(t)) - clear_gj(t)) + s_kg >= 0``;
* wall w: ``mask_w (d_w(p) - (radius + wall margin)) + s_k,wall >= 0``, d_w the distance to the segment, negative
  beyond it (signed by the side the robot is on now, where p projects inside the segment): a plan cannot jump
  through a wall between knots.

Hard constraints: z_0 equals the measured state, velocity and acceleration bounds.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from planner.config import MPCConfig
from planner.dynamics import model_dims, robot_dynamics
from planner.jit import compiled_nlpsol
from planner.scene import SceneArrays

EPS_DIST_M2 = 1e-6
HUBER_M = 0.1
WALL_END_BLEND_M = 0.05  # how far past a wall's end its far side still counts as beyond the wall (_wall_dist)


@dataclass(frozen=True)
class Sizes:
    """Sizes: state nz, control nu, slacks per stage ns, horizon H, peds M, modes K, groups G, walls W,
    clearance checks per plan step ``sub`` (1: at the knots; 2: at the knots and half-way)."""

    nz: int
    nu: int
    ns: int
    h: int
    m: int
    k: int
    g: int
    w: int
    sub: int
    sides: bool = False  # guidance on: the pedestrians' constraints may be half-planes (planner/guidance.py)

    @staticmethod
    def from_config(cfg: MPCConfig) -> Sizes:
        dims = model_dims(cfg.robot.model)
        ns = 1 + (1 if cfg.max_groups else 0) + (1 if cfg.max_walls else 0)  # pedestrians, groups, walls
        return Sizes(dims.state_dim, dims.control_dim, ns, cfg.horizon_steps, cfg.max_peds, cfg.n_modes,
                     cfg.max_groups, cfg.max_walls, 2 if cfg.check_midpoints else 1, cfg.guidance is not None)

    @property
    def nt(self) -> int:
        """Number of checked times: sub * H, at (j + 1) * dt / sub for j = 0 .. nt - 1."""
        return self.sub * self.h


def param_shapes(sz: Sizes) -> dict[str, tuple[int, ...]]:
    """Shapes of the parameter blocks, in the order they are packed into the flat vector p. With guidance
    (``sz.sides``) two more: each pedestrian's half-plane normals and the switch between disc and half-plane."""
    shapes = {
        "z0": (sz.nz,), "goal": (2,),
        "ped_pos": (sz.nt, sz.m, sz.k, 2), "ped_clear": (sz.nt, sz.m), "ped_mask": (sz.m,),
        "grp_a": (sz.nt, sz.g, sz.k, 2), "grp_b": (sz.nt, sz.g, sz.k, 2), "grp_clear": (sz.nt, sz.g, sz.k),
        "grp_mask": (sz.g,), "walls": (sz.w, 4), "wall_mask": (sz.w,), "wall_side": (sz.w,),
    }
    if sz.sides:
        shapes.update(ped_normal=(sz.nt, sz.m, sz.k, 2), ped_side=(sz.m,))
    return shapes


def param_slices(sz: Sizes) -> dict[str, slice]:
    """Where each parameter block lies in the flat vector p."""
    out, offset = {}, 0
    for name, shape in param_shapes(sz).items():
        size = int(np.prod(shape))
        out[name] = slice(offset, offset + size)
        offset += size
    return out


def pack_params(sz: Sizes, z0: np.ndarray, goal: np.ndarray, scene: SceneArrays) -> np.ndarray:
    """Flat parameter vector (C order within each block). With guidance the half-plane switches are off (every
    pedestrian a disc): `planner.guidance` writes a guided solve's blocks over them."""
    values = {"z0": z0, "goal": goal, **{name: getattr(scene, name) for name in param_shapes(sz)
                                         if name not in ("z0", "goal", "ped_normal", "ped_side")}}
    if sz.sides:
        values.update(ped_normal=np.zeros((sz.nt, sz.m, sz.k, 2)), ped_side=np.zeros(sz.m))
    parts = []
    for name, shape in param_shapes(sz).items():
        arr = np.asarray(values[name], float)
        if arr.shape != shape:
            raise ValueError(f"parameter {name} has shape {arr.shape}, expected {shape}")
        parts.append(arr.ravel())
    return np.concatenate(parts)


def _symbolic_params(sz: Sizes) -> tuple[ca.SX, dict[str, np.ndarray]]:
    """Flat SX parameter vector and, per block, a numpy object array of its SX entries in block shape."""
    shapes = param_shapes(sz)
    total = sum(int(np.prod(s)) for s in shapes.values())
    p = ca.SX.sym("p", total)
    blocks, offset = {}, 0
    for name, shape in shapes.items():
        size = int(np.prod(shape))
        blocks[name] = np.array([p[offset + i] for i in range(size)], dtype=object).reshape(shape)
        offset += size
    return p, blocks


def _seg_dist(pos: ca.SX, a, b) -> ca.SX:
    """Smoothed distance (m) from pos (2,) to the segment a-b (sequences of two SX entries)."""
    ab = ca.vertcat(b[0] - a[0], b[1] - a[1])
    ap = ca.vertcat(pos[0] - a[0], pos[1] - a[1])
    t = ca.fmin(ca.fmax(ca.dot(ap, ab) / (ca.dot(ab, ab) + 1e-9), 0), 1)
    diff = ap - t * ab
    return ca.sqrt(ca.dot(diff, diff) + EPS_DIST_M2)


def _wall_dist(pos: ca.SX, a, b, side) -> ca.SX:
    """Distance (m) from pos (2,) to the wall a-b, negative beyond it. On the robot's side of the wall's line (``side``:
    +1 when the robot is left of a->b now, -1 right) it is the distance to the segment, as before; on the far side it
    falls to minus the distance to the line where pos projects inside the segment, blended smoothly (over
    ``WALL_END_BLEND_M``) into the distance to the segment beyond its ends. Unsigned, a plan could jump through a wall
    between two knots for a small slack (measured: in the corridors the MPC planned through the walls into the empty
    space behind them). The blend keeps the function smooth for the solvers (a hard switch at the ends made IPOPT
    cycle at a wall's end)."""
    ab = ca.vertcat(b[0] - a[0], b[1] - a[1])
    ap = ca.vertcat(pos[0] - a[0], pos[1] - a[1])
    length = ca.sqrt(ca.dot(ab, ab) + 1e-9)
    along = ca.dot(ap, ab) / length  # m from a along the wall
    perp = side * (ab[0] * ap[1] - ab[1] * ap[0]) / length  # m, > 0 on the robot's side
    dist = _seg_dist(pos, a, b)
    # logistic steps written with tanh, which saturates without overflow (exp overflowed for the far padding walls)
    half = 2 * WALL_END_BLEND_M
    inside = 0.25 * (1 + ca.tanh(along / half)) * (1 + ca.tanh((length - along) / half))
    return dist + 2 * inside * ca.fmin(perp, 0)


def _point_dist2(pos: ca.SX, q) -> ca.SX:
    return (pos[0] - q[0]) ** 2 + (pos[1] - q[1]) ** 2



def control_bounds(cfg: MPCConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-component control lower/upper bounds and acceleration bounds (per second)."""
    rc = cfg.robot
    if rc.model == "unicycle":
        lb = np.array([-rc.min_speed_mps, -rc.max_yaw_rate_radps])
        ub = np.array([rc.max_speed_mps, rc.max_yaw_rate_radps])
        return lb, ub, np.array([rc.max_accel_mps2, rc.max_yaw_accel_radps2])
    big = np.full(2, rc.max_speed_mps)
    return -big, big, np.full(2, rc.max_accel_mps2)


class _Builder:
    """Accumulates stage-local constraints and cost over stage-ordered symbols z_k, u_k, s_k."""

    def __init__(self, cfg: MPCConfig, sz: Sizes) -> None:
        self.cfg, self.sz = cfg, sz
        self.p, self.par = _symbolic_params(sz)
        self.z = [ca.SX.sym(f"z{k}", sz.nz) for k in range(sz.h + 1)]
        self.u = [ca.SX.sym(f"u{k}", sz.nu) for k in range(sz.h)]
        self.s = [ca.SX.sym(f"s{k}", sz.ns) for k in range(sz.h + 1)]
        self.g: list[ca.SX] = []
        self.lbg: list[float] = []
        self.ubg: list[float] = []
        self.ng = [0] * (sz.h + 1)
        self.cost = 0
        self.slack_min: list[ca.SX] = []

    def con(self, expr: ca.SX, lb, ub, stage: int | None) -> None:
        """Add constraints lb <= expr <= ub; ``stage`` None marks the dynamics (not a path constraint)."""
        n = expr.numel()
        self.g.append(expr)
        self.lbg += list(np.broadcast_to(lb, n).astype(float))
        self.ubg += list(np.broadcast_to(ub, n).astype(float))
        if stage is not None:
            self.ng[stage] += n


def _control_terms(b: _Builder, k: int) -> None:
    """Acceleration (and holonomic speed) constraints and effort/smoothness cost of stage k < H."""
    cfg, z, u = b.cfg, b.z[k], b.u[k]
    _, ub, accel = control_bounds(cfg)
    du = u - z[model_dims(cfg.robot.model).vel_slice]
    if cfg.robot.model == "unicycle":
        b.con(du, -accel * cfg.dt_s, accel * cfg.dt_s, k)
    else:
        b.con(ca.dot(du, du), -np.inf, (cfg.robot.max_accel_mps2 * cfg.dt_s) ** 2, k)
        b.con(ca.dot(u, u), -np.inf, cfg.robot.max_speed_mps**2, k)
    wts = cfg.weights
    b.cost += wts.effort * ca.sumsqr(u / ub) + wts.smoothness * ca.sumsqr(du / (accel * cfg.dt_s))


def _soft(b: _Builder, k: int, exprs: list[ca.SX], slack: ca.SX, need: list[ca.SX]) -> None:
    """Add ``exprs + slack >= 0`` to stage k and record the slack that makes them feasible."""
    if not exprs:
        need.append(ca.SX(0))
        return
    col = ca.vertcat(*exprs)
    b.con(col + slack, 0.0, np.inf, k)
    need.append(ca.mmax(-col))


def _checked_points(b: _Builder, k: int) -> list[tuple[ca.SX, int]]:
    """Robot positions checked in stage k with their time index: the knot p_k (k >= 1) and, with
    sub = 2, the half-step position f(z_k, u_k, dt/2) (k < H), which is local to stage k."""
    sz, points = b.sz, []
    if k > 0:
        points.append((b.z[k][:2], sz.sub * k - 1))
    if sz.sub == 2 and k < sz.h:
        half = robot_dynamics(b.cfg.robot.model)(b.z[k], b.u[k], b.cfg.dt_s / 2)
        points.append((half[:2], 2 * k))
    return points


def _social_cost(b: _Builder, k: int) -> None:
    """Social-comfort cost at the knot of stage k (1..H)."""
    cfg, sz, par = b.cfg, b.sz, b.par
    pos, t = b.z[k][:2], sz.sub * k - 1
    for m in range(sz.m):
        for j in range(sz.k):
            d2 = _point_dist2(pos, par["ped_pos"][t, m, j])
            b.cost += (cfg.weights.social / sz.k * par["ped_mask"][m]
                       * ca.exp(-d2 / (2 * cfg.comfort_distance_m**2)))


def _collision_terms(b: _Builder, k: int) -> None:
    """Soft clearance constraints and slack cost of stage k (0..H): one slack shared by the pedestrians (all
    of them, their modes and the points checked in the stage), one by the group slots and one by the walls. A slack
    per pedestrian made every solve ~25% slower per iteration (fatrop's stage size grows with the slacks) and failed
    more often, for the same plans where nothing is violated (docs/decisions/planner-settings.md, item 7)."""
    cfg, sz, par = b.cfg, b.sz, b.par
    points, s, need = _checked_points(b, k), b.s[k], []
    exprs = [par["ped_mask"][m] * _ped_gap(b, pos, t, m, j) for m in range(sz.m) for pos, t in points
             for j in range(sz.k)]
    _soft(b, k, exprs, s[0], need)
    if sz.g:
        exprs = [par["grp_mask"][gi] * (_seg_dist(pos, par["grp_a"][t, gi, j], par["grp_b"][t, gi, j])
                                        - par["grp_clear"][t, gi, j])
                 for gi in range(sz.g) for pos, t in points for j in range(sz.k)]
        _soft(b, k, exprs, s[1], need)
    if sz.w:
        clear = cfg.wall_clearance_m
        exprs = [par["wall_mask"][i] * (_wall_dist(pos, par["walls"][i, :2], par["walls"][i, 2:],
                                                   par["wall_side"][i]) - clear)
                 for pos, _ in points for i in range(sz.w)]
        _soft(b, k, exprs, s[sz.ns - 1], need)
    b.slack_min.append(ca.fmax(ca.vertcat(*need), 0))
    b.cost += cfg.weights.slack_l1 * ca.sum1(s) + cfg.weights.slack_l2 * ca.sumsqr(s)


def _ped_gap(b: _Builder, pos: ca.SX, t: int, m: int, j: int) -> ca.SX:
    """Clearance margin (m) of pos from pedestrian m, mode j at checked time t: the distance beyond the clearance;
    with guidance, blended by the switch ``ped_side`` (0: that distance, 1: the signed distance beyond the clearance
    along the half-plane's normal ``ped_normal``, planner/guidance.py)."""
    par, q = b.par, b.par["ped_pos"][t, m, j]
    disc = ca.sqrt(_point_dist2(pos, q) + EPS_DIST_M2) - par["ped_clear"][t, m]
    if not b.sz.sides:
        return disc
    n, on = par["ped_normal"][t, m, j], par["ped_side"][m]
    plane = n[0] * (pos[0] - q[0]) + n[1] * (pos[1] - q[1]) - par["ped_clear"][t, m]
    return (1 - on) * disc + on * plane


def _goal_cost(b: _Builder, k: int) -> None:
    goal, z = b.par["goal"], b.z[k]
    hub = ca.sqrt((z[0] - goal[0]) ** 2 + (z[1] - goal[1]) ** 2 + HUBER_M**2) - HUBER_M
    weight = b.cfg.weights.goal + (b.cfg.weights.goal_terminal if k == b.sz.h else 0.0)
    b.cost += weight * hub


def _build_constraints(b: _Builder) -> None:
    """Constraints in fatrop order: dyn_0, path_0, dyn_1, path_1, ..., path_H."""
    f = robot_dynamics(b.cfg.robot.model)
    for k in range(b.sz.h + 1):
        if k < b.sz.h:
            b.con(b.z[k + 1] - f(b.z[k], b.u[k], b.cfg.dt_s), 0.0, 0.0, None)
        if k == 0:
            b.con(b.z[0] - ca.vertcat(*b.par["z0"]), 0.0, 0.0, 0)
        if k < b.sz.h:
            _control_terms(b, k)
        _collision_terms(b, k)
        if k > 0:
            _social_cost(b, k)
            _goal_cost(b, k)


@dataclass(frozen=True)
class Layout:
    """Index arrays into the flat decision vector: z (H+1, nz), u (H, nu), s (H+1, ns)."""

    z: np.ndarray
    u: np.ndarray
    s: np.ndarray
    n: int

    @staticmethod
    def from_sizes(sz: Sizes) -> Layout:
        z, u, s, off = [], [], [], 0
        for k in range(sz.h + 1):
            z.append(np.arange(off, off + sz.nz))
            off += sz.nz
            if k < sz.h:
                u.append(np.arange(off, off + sz.nu))
                off += sz.nu
            s.append(np.arange(off, off + sz.ns))
            off += sz.ns
        return Layout(np.array(z), np.array(u), np.array(s), off)

    def variables(self, b: _Builder) -> ca.SX:
        parts = []
        for k in range(b.sz.h + 1):
            parts.append(b.z[k])
            if k < b.sz.h:
                parts.append(b.u[k])
            parts.append(b.s[k])
        return ca.vertcat(*parts)


def _solver_options(cfg: MPCConfig, b: _Builder) -> dict:
    if cfg.solver == "ipopt":
        return {"expand": True, "print_time": False, "ipopt": {
            "print_level": 5 if cfg.verbose else 0, "sb": "yes", "tol": cfg.tolerance,
            "acceptable_tol": 10 * cfg.tolerance, "acceptable_iter": 3, "max_iter": cfg.max_iter,
            "max_wall_time": cfg.time_budget_s, "mu_init": 1e-3,
            # Trust the (shifted or rolled-out) initial guess: measured ~10-15% fewer CPU ms per solve.
            "warm_start_init_point": "yes", "warm_start_bound_push": 1e-6,
            "warm_start_mult_bound_push": 1e-6}}
    sz = b.sz
    nu = [sz.nu + sz.ns] * sz.h + [sz.ns]
    eq = [lo == hi for lo, hi in zip(b.lbg, b.ubg, strict=True)]
    return {"expand": True, "print_time": False, "structure_detection": "manual", "N": sz.h,
            "nx": [sz.nz] * (sz.h + 1), "nu": nu, "ng": b.ng, "equality": eq,
            "fatrop": {"print_level": 10 if cfg.verbose else 0, "max_iter": cfg.max_iter,
                       "tolerance": cfg.tolerance, "tol_acceptable": 10 * cfg.tolerance,
                       "acceptable_iter": 3}}


@dataclass(frozen=True)
class OCP:
    """A built NLP: ``solver`` (casadi nlpsol Function; ``guided_solver`` the same with the guidance layer's
    iteration cap), ``slack_fn(w, p) -> minimal slacks ((H+1)*ns)``,
    ``cost_fn(w, p) -> objective``, variable layout, bounds, and sizes."""

    solver: ca.Function
    slack_fn: ca.Function
    cost_fn: ca.Function
    layout: Layout
    sizes: Sizes
    lbx: np.ndarray
    ubx: np.ndarray
    lbg: np.ndarray
    ubg: np.ndarray
    guided_solver: ca.Function | None = None  # with guidance: the same NLP, capped at GuidanceConfig.max_iter


def build_ocp(cfg: MPCConfig) -> OCP:
    """Build the NLP and its solver once for ``cfg`` (sizes are fixed from then on)."""
    if not ca.has_nlpsol(cfg.solver):
        raise ValueError(f"this CasADi build ({ca.__version__}) has no {cfg.solver!r} plugin; "
                         "use solver='ipopt'")
    sz = Sizes.from_config(cfg)
    b = _Builder(cfg, sz)
    _build_constraints(b)
    layout = Layout.from_sizes(sz)
    w = layout.variables(b)
    lbx, ubx = np.full(layout.n, -np.inf), np.full(layout.n, np.inf)
    lb_u, ub_u, _ = control_bounds(cfg)
    lbx[layout.u], ubx[layout.u] = lb_u, ub_u
    lbx[layout.s] = 0.0
    nlp = {"x": w, "p": b.p, "f": b.cost, "g": ca.vertcat(*b.g)}
    opts = _solver_options(cfg, b)
    solver = compiled_nlpsol("mpc", cfg.solver, nlp, opts, ca.nlpsol("mpc", cfg.solver, nlp, opts))
    guided = None
    if cfg.guidance is not None:
        capped = _solver_options(replace(cfg, max_iter=cfg.guidance.max_iter), b)
        guided = compiled_nlpsol("mpc", cfg.solver, nlp, capped, ca.nlpsol("mpc", cfg.solver, nlp, capped))
    slack_fn = ca.Function("slack_min", [w, b.p], [ca.vertcat(*b.slack_min)])
    cost_fn = ca.Function("cost", [w, b.p], [b.cost])
    return OCP(solver, slack_fn, cost_fn, layout, sz, lbx, ubx, np.array(b.lbg), np.array(b.ubg), guided)
