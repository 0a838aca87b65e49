"""Social forces as vectorised pure functions of arrays.

Every function returns accelerations in m/s^2 (force per unit mass), shape (N, 2). Inputs are the
active pedestrians only: positions `pos` (N, 2) m, velocities `vel` (N, 2) m/s, radii (N,) m, headings
`e` (N, 2) unit vectors (walking direction), group labels (N,) int.
"""

from __future__ import annotations

import numpy as np

from crowdsim.config import GroupForceParams, SocialForceParams

_EPS = 1e-9


def unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Row-wise unit vectors and norms of v (..., 2); zero rows give a zero unit vector."""
    norm = np.sqrt(np.einsum("...k,...k->...", v, v))
    safe = np.where(norm > _EPS, norm, 1.0)
    return v / safe[..., None] * (norm > _EPS)[..., None], norm


def desired_velocity(pos: np.ndarray, goal: np.ndarray, speed: np.ndarray,
                     params: SocialForceParams) -> np.ndarray:
    """(N, 2) desired velocity: towards the goal at `speed` (N,), ramping to zero inside the slowdown radius."""
    e, dist = unit(goal - pos)
    ramp = np.clip(dist / params.slowdown_radius_m, 0.0, 1.0)
    return e * (speed * ramp)[:, None]


def driving_acc(vel: np.ndarray, v_desired: np.ndarray, params: SocialForceParams) -> np.ndarray:
    """Relaxation towards the desired velocity: (v_desired - v) / tau."""
    return (v_desired - vel) / params.relaxation_time_s


def pair_terms(diff: np.ndarray, r_sum: np.ndarray, e_i: np.ndarray, e_j: np.ndarray,
               params: SocialForceParams) -> tuple[np.ndarray, np.ndarray]:
    """Repulsion within P pairs: (acc on i, acc on j), each (P, 2).

    diff = pos_i - pos_j (P, 2), r_sum = r_i + r_j (P,), e_i / e_j headings (P, 2). The magnitude is
    A exp((r_sum - d) / B); each side is weighted by its own anisotropy factor
    w = lam + (1 - lam)(1 + cos phi) / 2, phi the angle between its heading and the direction to the
    other. With lam = 1 the two accelerations are exactly opposite (Newton's third law).
    """
    n, dist = unit(diff)
    mag = params.ped_strength_mps2 * np.exp((r_sum - dist) / params.ped_range_m)
    lam = params.anisotropy
    cos_i = -np.einsum("pk,pk->p", n, e_i)  # j ahead of i -> e_i points along -n
    cos_j = np.einsum("pk,pk->p", n, e_j)
    w_i = lam + (1.0 - lam) * 0.5 * (1.0 + cos_i)
    w_j = lam + (1.0 - lam) * 0.5 * (1.0 + cos_j)
    return n * (mag * w_i)[:, None], -n * (mag * w_j)[:, None]


def scatter_add(n: int, idx: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Sum rows of values (P, k) into an (n, k) array at indices idx (P,)."""
    out = np.empty((n, values.shape[1]))
    for k in range(values.shape[1]):
        out[:, k] = np.bincount(idx, weights=values[:, k], minlength=n)
    return out


def pedestrian_acc(pos: np.ndarray, radius: np.ndarray, e: np.ndarray, i: np.ndarray, j: np.ndarray,
                   params: SocialForceParams, label: np.ndarray | None = None,
                   member_scale: float = 1.0) -> np.ndarray:
    """(N, 2) total pedestrian repulsion given neighbour pairs (i, j) (P,) from the spatial index.

    label: (N,) group labels (negative: in no group, e.g. the robot); the repulsion between two rows with the same
    non-negative label (members of one group) is multiplied by member_scale in [0, 1]
    (`GroupForceParams.member_ped_repulsion_scale`). Without labels every pair repels fully.
    """
    acc_i, acc_j = pair_terms(pos[i] - pos[j], radius[i] + radius[j], e[i], e[j], params)
    if label is not None and member_scale != 1.0:
        scale = np.where((label[i] == label[j]) & (label[i] >= 0), member_scale, 1.0)[:, None]
        acc_i, acc_j = acc_i * scale, acc_j * scale
    n = len(pos)
    return scatter_add(n, i, acc_i) + scatter_add(n, j, acc_j)


def closest_points_on_segments(pos: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """(N, S, 2) closest point on each segment (S, 2, 2) to each position (N, 2). A declared twin of
    `planner.segment_projection` (crowdsim may not import the planner), checked in tests/test_shared_facts.py."""
    a = segments[:, 0]
    ab = segments[:, 1] - a
    len2 = np.maximum(np.einsum("sk,sk->s", ab, ab), _EPS)
    t = np.einsum("nsk,sk->ns", pos[:, None, :] - a[None], ab) / len2
    t = np.clip(t, 0.0, 1.0)
    return a[None] + t[..., None] * ab[None]


def wall_acc(pos: np.ndarray, radius: np.ndarray, segments: np.ndarray,
             params: SocialForceParams) -> np.ndarray:
    """(N, 2) wall repulsion A_w exp((r - d) / B_w) from every segment (S, 2, 2) closer than the cut-off."""
    if len(segments) == 0 or len(pos) == 0:
        return np.zeros((len(pos), 2))
    n, dist = unit(pos[:, None, :] - closest_points_on_segments(pos, segments))
    mag = params.wall_strength_mps2 * np.exp((radius[:, None] - dist) / params.wall_range_m)
    mag = np.where(dist < params.cutoff_m, mag, 0.0)
    return np.einsum("ns,nsk->nk", mag, n)


def _gaze_and_catch_up(pos: np.ndarray, vel: np.ndarray, e: np.ndarray, speed: np.ndarray, look: np.ndarray,
                       params: GroupForceParams) -> np.ndarray:
    """(N, 2) gaze brake and catch-up push of each member towards the centre of the others of its `look` group
    (N,) dense labels (the whole group or its row); members with no others in it get none."""
    n_look = int(look.max()) + 1 if len(look) else 0
    count = np.bincount(look, minlength=n_look)[look].astype(float)
    total = scatter_add(n_look, look, pos)[look]
    others = (total - pos) / np.maximum(count - 1.0, 1.0)[:, None]
    to_others, dist_others = unit(others - pos)
    angle = np.arccos(np.clip(np.einsum("nk,nk->n", e, to_others), -1.0, 1.0))
    half = np.deg2rad(params.vision_half_angle_deg)
    alpha = np.maximum(angle - half, 0.0)
    behind = np.maximum(np.pi - half - angle, 0.0)  # how far the others are ahead of abreast (rad)
    fade = np.minimum(dist_others / params.gaze_fade_m, 1.0)  # the direction to a point at one's feet is moot
    looking = fade * (count > 1)
    acc = (params.catch_up_strength * behind * speed * looking)[:, None] * e
    acc -= (params.gaze_strength * alpha * looking)[:, None] * vel
    return acc


def group_acc(pos: np.ndarray, vel: np.ndarray, e: np.ndarray, label: np.ndarray, i: np.ndarray,
              j: np.ndarray, params: GroupForceParams, gaze_label: np.ndarray | None = None,
              v_desired: np.ndarray | None = None) -> np.ndarray:
    """(N, 2) Moussaïd et al. (2010) group terms: gaze, coherence and intra-group repulsion, plus the catch-up
    term (`GroupForceParams`): beta1' gamma min(|v|, |v_desired|) along the heading for a member whose others'
    centre lies gamma rad ahead of abreast, the mirror of the gaze brake.

    label: (N,) dense group labels 0..G-1. v_desired: (N, 2) m/s desired velocities (default: vel); a member
    standing at its place (desired speed ~0) or stuck (speed ~0) is not pushed. gaze_label: (N,) dense labels of
    the sub-groups whose centre each member looks at (default: the whole group); groups above three walk as
    sub-groups (Moussaïd et al. 2010). A member of a group split into sub-groups directs the share
    `params.whole_group_gaze_share` of its gaze and catch-up at the whole group's other members and the rest at
    its own sub-group's, so the front row is held back by the row behind only that much.
    Pairs (i, j) from the spatial index are reused for the repulsion between members closer than d0. Singletons
    receive no group force.
    """
    n = len(pos)
    gaze_label = label if gaze_label is None else gaze_label
    v_desired = vel if v_desired is None else v_desired
    n_groups = int(label.max()) + 1 if n else 0
    size = np.bincount(label, minlength=n_groups)[label].astype(float)
    in_group = size > 1
    centre = scatter_add(n_groups, label, pos)[label] / size[:, None]
    # Gaze: rotate the head towards the other members' centre (of one's sub-group); beyond the vision field,
    # slow down; catch up with others ahead of abreast.
    speed = np.minimum(unit(v_desired)[1], unit(vel)[1])
    acc = _gaze_and_catch_up(pos, vel, e, speed, gaze_label, params)  # none for singletons
    n_sub = int(gaze_label.max()) + 1 if n else 0
    split = np.bincount(gaze_label, minlength=n_sub)[gaze_label] < size  # one's sub-group is not the whole group
    share = params.whole_group_gaze_share
    if share > 0 and split.any():
        whole = _gaze_and_catch_up(pos, vel, e, speed, label, params)
        acc[split] = (1.0 - share) * acc[split] + share * whole[split]
    # Coherence: attraction to the centre of mass once farther than (n - 1) / 2 m (smoothed over 0.25 m).
    to_centre, d_centre = unit(centre - pos)
    q = np.clip((d_centre - 0.5 * (size - 1.0)) / 0.25, 0.0, 1.0) * in_group
    acc += params.coherence_strength_mps2 * q[:, None] * to_centre
    # Repulsion between members closer than d0.
    same = label[i] == label[j]
    ii, jj = i[same], j[same]
    nvec, dist = unit(pos[ii] - pos[jj])
    rep = nvec * (params.repulsion_strength_mps2 * (dist < params.repulsion_distance_m))[:, None]
    acc += scatter_add(n, ii, rep) - scatter_add(n, jj, rep)
    return acc


def headings(vel: np.ndarray, v_desired: np.ndarray, min_speed_mps: float = 0.1) -> np.ndarray:
    """(N, 2) walking direction: the velocity direction, or the desired direction when nearly at rest."""
    e_v, speed = unit(vel)
    e_d, _ = unit(v_desired)
    return np.where((speed > min_speed_mps)[:, None], e_v, e_d)


def cap_speed(vel: np.ndarray, max_speed: np.ndarray) -> np.ndarray:
    """Scale rows of vel (N, 2) whose norm exceeds max_speed (N,) back onto the limit."""
    speed = np.sqrt(np.einsum("nk,nk->n", vel, vel))
    scale = np.where(speed > max_speed, max_speed / np.maximum(speed, _EPS), 1.0)
    return vel * scale[:, None]


def crossed_walls(start: np.ndarray, end: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """(n,) bool: whether the move start -> end (n, 2) m crosses any wall segment (S, 2, 2) m, i.e. the two
    segments properly intersect (a move that only touches a wall or runs along it does not count)."""
    if len(start) == 0 or len(segments) == 0:
        return np.zeros(len(start), bool)
    a, b = segments[None, :, 0], segments[None, :, 1]  # (1, S, 2)
    p, q = start[:, None], end[:, None]  # (n, 1, 2)

    def cross(o: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return (u[..., 0] - o[..., 0]) * (v[..., 1] - o[..., 1]) - (u[..., 1] - o[..., 1]) * (v[..., 0] - o[..., 0])

    d1, d2 = cross(a, b, p), cross(a, b, q)  # sides of the wall line the move starts and ends on
    d3, d4 = cross(p, q, a), cross(p, q, b)  # sides of the move line the wall's ends are on
    return ((d1 * d2 < 0) & (d3 * d4 < 0)).any(axis=1)
