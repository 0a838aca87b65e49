"""Scenario registry: geometry (wall segments), where groups come from and where they go.

A scenario is data plus three small methods; `make_scenario(name, options)` builds one from the
registry and raises an error listing the valid names for an unknown one.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from crowdsim.names import did_you_mean, unknown_name

Rect = tuple[float, float, float, float]  # xmin, ymin, xmax, ymax in metres


@dataclass(frozen=True)
class Flow:
    """Groups appear in `spawn` and head to a point drawn in `target` (both rectangles, m)."""

    spawn: Rect
    target: Rect


@dataclass(frozen=True)
class Scenario:
    """Static description of one scene.

    walls: (S, 2, 2) segments in metres. flows: origin/destination rectangles. on_arrival: "remove"
    (leave the scene), "stop" (stand at the goal) or "new_goal" (draw a new destination). continuous:
    keep the crowd size by spawning new groups as others leave. periodic_x: (x0, x1) wraps a pedestrian
    who passes x1 back to x0 (used to hold a corridor at a fixed density). stop_areas and pois: where groups
    that stop (`crowdsim.behaviours`) stand; none means nobody stops in this scene.
    """

    name: str
    walls: np.ndarray
    bounds: Rect
    flows: tuple[Flow, ...]
    on_arrival: str = "remove"
    continuous: bool = True
    periodic_x: tuple[float, float] | None = None
    exit_radius_m: float = 1.0
    dense_spawn: Rect | None = None  # initial crowd placed on a lattice here instead of by flows
    interior: Rect | None = None  # initial groups start anywhere in here (instead of along their flow)
    stop_areas: tuple[Rect, ...] = ()  # where a group may stop and stand (BehaviourConfig stops)
    pois: tuple[tuple[float, float], ...] = ()  # points of interest (x, y) m that people stop at
    options: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.on_arrival not in ("remove", "stop", "new_goal"):
            raise ValueError(f"on_arrival must be remove, stop or new_goal, got {self.on_arrival!r}")
        walls = np.asarray(self.walls, dtype=float).reshape(-1, 2, 2)
        if not np.all(np.isfinite(walls)):
            raise ValueError(f"scenario {self.name}: wall coordinates must be finite")
        object.__setattr__(self, "walls", walls)
        for k, flow in enumerate(self.flows):
            for what, rect in (("spawn", flow.spawn), ("target", flow.target)):
                _check_rect(self.name, f"flow {k} {what}", rect, walls)
        for k, rect in enumerate(self.stop_areas):
            _check_rect(self.name, f"stop area {k}", rect, walls)

    def draw_flow(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """A group's origin (2,) and destination (2,), metres."""
        flow = self.flows[int(rng.integers(len(self.flows)))]
        return _uniform_in(rng, flow.spawn), _uniform_in(rng, flow.target)

    def new_destination(self, rng: np.random.Generator, pos: np.ndarray) -> np.ndarray:
        """A destination (2,) for a group at pos (2,) that needs a new goal: the target of a random flow
        whose target does not contain pos."""
        for _ in range(20):
            flow = self.flows[int(rng.integers(len(self.flows)))]
            if not _contains(flow.target, pos):
                return _uniform_in(rng, flow.target)
        return _uniform_in(rng, self.flows[0].target)


def _uniform_in(rng: np.random.Generator, rect: Rect) -> np.ndarray:
    return np.array([rng.uniform(rect[0], rect[2]), rng.uniform(rect[1], rect[3])])


def _contains(rect: Rect, p: np.ndarray) -> bool:
    return bool(rect[0] <= p[0] <= rect[2] and rect[1] <= p[1] <= rect[3])


def _segment_hits_rect(a: np.ndarray, b: np.ndarray, rect: Rect) -> bool:
    """Whether segment ab passes through the open interior of rect (Liang–Barsky clipping)."""
    x0, y0, x1, y1 = rect
    d = b - a
    t0, t1 = 0.0, 1.0
    for p, q in ((-d[0], a[0] - x0), (d[0], x1 - a[0]), (-d[1], a[1] - y0), (d[1], y1 - a[1])):
        if abs(p) < 1e-12:
            if q <= 0:
                return False
            continue
        t = q / p
        if p < 0:
            t0 = max(t0, t)
        else:
            t1 = min(t1, t)
        if t0 >= t1:
            return False
    return True


def _check_rect(name: str, what: str, rect: Rect, walls: np.ndarray) -> None:
    if len(rect) != 4 or not all(np.isfinite(rect)) or rect[0] > rect[2] or rect[1] > rect[3]:
        raise ValueError(f"scenario {name}: {what} area {rect} must be (xmin, ymin, xmax, ymax)")
    for a, b in walls:
        if _segment_hits_rect(a, b, rect):
            raise ValueError(f"scenario {name}: {what} area {rect} lies across the wall {a.tolist()}-{b.tolist()}")


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


SCENARIOS: dict[str, Callable[[Mapping[str, float]], Scenario]] = {
    "corridor": corridor,
    "crossing": crossing,
    "bottleneck": bottleneck,
    "plaza": plaza,
    "circle_crossing": circle_crossing,
    "open": open_space,
}


# The options each scenario reads (`SimConfig.scenario_options`), with their defaults. Lengths (`_m`) must be
# > 0; `density` (people/m², dense initial placement) >= 0; `periodic` / `continuous` are 0 or 1 flags.
SCENARIO_OPTIONS: dict[str, dict[str, float]] = {
    "corridor": {"length_m": 20.0, "width_m": 4.0, "periodic": 0.0, "density": 0.0},
    "crossing": {"half_length_m": 10.0, "width_m": 6.0},
    "bottleneck": {"room_m": 8.0, "door_m": 1.0, "density": 0.0, "continuous": 1.0},
    "plaza": {"size_m": 20.0, "gate_m": 4.0},
    "circle_crossing": {"radius_m": 6.0},
    "open": {"size_m": 30.0},
}
_FLAGS = ("periodic", "continuous")


def check_options(name: str, options: Mapping[str, float]) -> None:
    """Raise ValueError for an unknown scenario, an option it does not read (listing the valid ones) or a value
    out of range (lengths > 0, density >= 0, flags 0 or 1, everything finite)."""
    if name not in SCENARIOS:
        raise ValueError(unknown_name("scenario", name, sorted(SCENARIOS)))
    valid = SCENARIO_OPTIONS[name]
    for key, value in options.items():
        if key not in valid:
            raise ValueError(f"scenario {name!r} has no option {key!r};{did_you_mean(key, valid)} valid options: "
                             f"{', '.join(valid)}")
        value = float(value)
        if not np.isfinite(value):
            raise ValueError(f"scenario option {key} must be finite, got {value!r}")
        if key.endswith("_m") and value <= 0:
            raise ValueError(f"scenario option {key} must be > 0 m, got {value!r}")
        if key == "density" and value < 0:
            raise ValueError(f"scenario option density must be >= 0 people/m^2, got {value!r}")
        if key in _FLAGS and value not in (0.0, 1.0):
            raise ValueError(f"scenario option {key} is a flag: 0 or 1, got {value!r}")


def make_scenario(name: str, options: Mapping[str, float] | None = None) -> Scenario:
    """Build a registered scenario; an unknown name or option raises a ValueError listing the valid ones."""
    check_options(name, dict(options or {}))
    return SCENARIOS[name](dict(options or {}))
