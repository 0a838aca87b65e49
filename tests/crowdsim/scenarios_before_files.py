"""Frozen copy of the scenario builders as Python functions, as they were before the scenarios became TOML files
(`crowdsim/builtin_scenarios/`). Only `tests/crowdsim/test_scenario_files.py` uses it: the files must build the
very same scenarios, bit for bit, so that every recorded episode stays the same. Do not edit."""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from crowdsim.scenarios import Flow, Scenario


def corridor(opt: Mapping[str, float]) -> Scenario:
    """Bidirectional corridor, length x width (default 20 x 4 m). `periodic=1` makes it a one-way ring
    (every pedestrian walks +x and wraps at the end), used to hold a fixed density."""
    length, width = opt.get("length_m", 20.0), opt.get("width_m", 4.0)
    walls = [[[-2.0, 0.0], [length + 2.0, 0.0]], [[-2.0, width], [length + 2.0, width]]]
    m = 0.4
    right = Flow((0.0, m, 1.5, width - m), (length + 1.0, m, length + 1.5, width - m))
    left = Flow((length - 1.5, m, length, width - m), (-1.5, m, -1.0, width - m))
    if opt.get("periodic", 0.0):
        dense = (0.3, 0.3, length - 0.3, width - 0.3) if opt.get("density", 0.0) > 0 else None
        return Scenario("corridor", np.array(walls), (-2.0, 0.0, length + 2.0, width),
                        (Flow((0.0, m, length, width - m), (length + 1.0, m, length + 1.5, width - m)),),
                        continuous=False, periodic_x=(0.0, length), dense_spawn=dense, options=dict(opt))
    # people stop along the walls (not in the entrance zones), leaving the middle of a 4 m corridor free
    bands = ((3.0, 0.85, length - 3.0, 1.0), (3.0, width - 1.0, length - 3.0, width - 0.85)) if width >= 3.5 else ()
    return Scenario("corridor", np.array(walls), (-2.0, 0.0, length + 2.0, width), (right, left),
                    stop_areas=bands, options=dict(opt))


def crossing(opt: Mapping[str, float]) -> Scenario:
    """Two perpendicular flows (west->east and south->north) through a cross of two 6 m wide streets."""
    half, w = opt.get("half_length_m", 10.0), opt.get("width_m", 6.0) / 2.0
    walls = []
    for sx in (-1, 1):
        for sy in (-1, 1):
            corner = [sx * w, sy * w]
            walls.append([[sx * half, sy * w], corner])
            walls.append([corner, [sx * w, sy * half]])
    m = 0.4
    east = Flow((-half, -w + m, -half + 2.0, w - m), (half + 1.0, -w + m, half + 1.5, w - m))
    north = Flow((-w + m, -half, w - m, -half + 2.0), (-w + m, half + 1.0, w - m, half + 1.5))
    # people stop on the pavements of the four arms, beside the walls, away from the entrances
    near, far = w + 1.0, half - 3.0
    bands = tuple(rect for rect in (
        (near, w - 1.0, far, w - 0.85), (-far, -w + 0.85, -near, -w + 1.0),
        (w - 1.0, -far, w - 0.85, -near), (-w + 0.85, near, -w + 1.0, far)) if rect[0] < rect[2] and rect[1] < rect[3])
    return Scenario("crossing", np.array(walls), (-half, -half, half, half), (east, north), stop_areas=bands,
                    options=dict(opt))


def bottleneck(opt: Mapping[str, float]) -> Scenario:
    """A room (default 8 x 8 m) emptying through a door (default 1.0 m wide) into a short corridor.

    `density` > 0 fills the back of the room on a lattice at that many persons per m^2 at start.
    """
    size, door = opt.get("room_m", 8.0), opt.get("door_m", 1.0)
    y0, y1 = size / 2.0 - door / 2.0, size / 2.0 + door / 2.0
    walls = [
        [[0.0, 0.0], [size, 0.0]], [[0.0, size], [size, size]], [[0.0, 0.0], [0.0, size]],
        [[size, 0.0], [size, y0]], [[size, y1], [size, size]],
        [[size, y0], [size + 2.0, y0]], [[size, y1], [size + 2.0, y1]],
    ]
    m = 0.4
    flow = Flow((m, m, size / 2.0, size - m), (size + 3.0, y0 + 0.2, size + 3.5, y1 - 0.2))
    dense = (m, m, size - m, size - m) if opt.get("density", 0.0) > 0 else None
    return Scenario("bottleneck", np.array(walls), (0.0, 0.0, size + 4.0, size), (flow,),
                    continuous=bool(opt.get("continuous", 1.0)), dense_spawn=dense, options=dict(opt))


def plaza(opt: Mapping[str, float]) -> Scenario:
    """Open square plaza (default 20 x 20 m) with an entrance in the middle of each side; groups walk
    between random entrances, continuously replaced as they leave, so a recording can run for hours."""
    s, gate = opt.get("size_m", 20.0), opt.get("gate_m", 4.0)
    g0, g1 = s / 2.0 - gate / 2.0, s / 2.0 + gate / 2.0
    walls = []
    for a, b in (([0, 0], [s, 0]), ([s, 0], [s, s]), ([s, s], [0, s]), ([0, s], [0, 0])):
        a, b = np.array(a, float), np.array(b, float)
        d = (b - a) / s
        walls += [[a, a + d * g0], [a + d * g1, b]]
    m = 0.4
    gates = [
        ((g0 + m, m, g1 - m, 1.5), (g0 + m, -1.5, g1 - m, -1.0)),  # south
        ((g0 + m, s - 1.5, g1 - m, s - m), (g0 + m, s + 1.0, g1 - m, s + 1.5)),  # north
        ((m, g0 + m, 1.5, g1 - m), (-1.5, g0 + m, -1.0, g1 - m)),  # west
        ((s - 1.5, g0 + m, s - m, g1 - m), (s + 1.0, g0 + m, s + 1.5, g1 - m)),  # east
    ]
    flows = tuple(Flow(gates[a][0], gates[b][1]) for a in range(4) for b in range(4) if a != b)
    # groups stop anywhere but in the entrances' approaches; two points of interest (a kiosk, a notice board)
    pois = ((0.3 * s, 0.7 * s), (0.7 * s, 0.3 * s))
    return Scenario("plaza", np.array(walls), (0.0, 0.0, s, s), flows, interior=(1.0, 1.0, s - 1.0, s - 1.0),
                    stop_areas=((2.5, 2.5, s - 2.5, s - 2.5),) if s > 6.0 else (), pois=pois, options=dict(opt))


def circle_crossing(opt: Mapping[str, float]) -> Scenario:
    """CrowdNav-style circle crossing: groups start on a circle (default radius 6 m) and walk to the
    opposite side; on arrival they draw a new crossing, so the scene never empties."""
    r = opt.get("radius_m", 6.0)
    n_arc = 24
    flows = []
    for k in range(n_arc):
        a = 2 * np.pi * k / n_arc
        p, q = r * np.array([np.cos(a), np.sin(a)]), -r * np.array([np.cos(a), np.sin(a)])
        flows.append(Flow((p[0] - 0.75, p[1] - 0.75, p[0] + 0.75, p[1] + 0.75),
                          (q[0] - 0.5, q[1] - 0.5, q[0] + 0.5, q[1] + 0.5)))
    return Scenario("circle_crossing", np.zeros((0, 2, 2)), (-r - 1, -r - 1, r + 1, r + 1), tuple(flows),
                    on_arrival="new_goal", continuous=False, exit_radius_m=0.5, options=dict(opt))


def open_space(opt: Mapping[str, float]) -> Scenario:
    """Empty ground with no walls; pedestrians stop at their goals (used for free-walking checks)."""
    size = opt.get("size_m", 30.0)
    flow = Flow((0.0, 0.0, 1.0, size), (size - 1.0, 0.0, size, size))
    return Scenario("open", np.zeros((0, 2, 2)), (0.0, 0.0, size, size), (flow,), on_arrival="stop",
                    continuous=False, options=dict(opt))



BUILDERS: dict[str, Callable[[Mapping[str, float]], Scenario]] = {
    "corridor": corridor,
    "crossing": crossing,
    "bottleneck": bottleneck,
    "plaza": plaza,
    "circle_crossing": circle_crossing,
    "open": open_space,
}
