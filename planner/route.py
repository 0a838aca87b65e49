"""A global route through the walls, so that the local MPC has a goal it can reach.

The MPC is local: its horizon (4 s) sees a few metres, and its goal cost pulls straight at the goal. With the goal
behind a wall (a door, a corner) it slides along the wall and never finds the way round. The route layer gives it
a subgoal (a "carrot") on a shortest path through the walls instead:

* `grid_route`: a shortest path on an 8-connected grid (cells of `RouteConfig.cell_m`) over the free space, the
  cells at least the MPC's wall clearance (robot radius + wall margin) from every wall segment. Each step costs
  its length times (1 + `clearance_weight` * max(0, `comfort_m` - clearance) / `comfort_m`), so the path keeps to
  the middle of doors and corridors. Solved with scipy's Dijkstra (imported only when a route is searched) once
  per goal and wall map. The grid itself (every cell's wall clearance, ~50 ms for a crowdnav-v1 room, and the
  graph) depends only on the walls and the lattice, so a `Router` keeps them (`GridCache`) and a search from
  elsewhere in the same room reuses them: the same arrays, so the same path.
* `Router.subgoal`: where the goal is in sight (the straight segment keeps the clearance from every wall), the goal
  itself, so that scenes without walls in the way plan exactly as without a router. Otherwise the farthest path
  point within `lookahead_m` (along the path, from the point nearest the robot) that the robot can see, slid
  forward along the path to `lookahead_m` from the robot when it is nearer, so that the MPC does not brake at a
  corner. The route is searched again when the goal or the walls change, or when the robot strays more than
  `replan_distance_m` from it.

Units: metres. Walls are segments (W, 4) x0, y0, x1, y1, as everywhere in the planner.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.config import RouteConfig
from planner.scene import wall_clearance

NEIGHBOURS = ((1, 0), (0, 1), (1, 1), (1, -1))  # half of the 8 neighbours; edges are undirected
GRID_CACHE_SIZE = 4  # grids a GridCache keeps (one per wall map and lattice; an env has one wall map)
CLEARANCE_SLACK_CELLS = 40  # a clearance field is computed this many cells beyond the grid asked for (+x and +y)


@dataclass(frozen=True)
class RouteGrid:
    """The search grid of one wall map and lattice: cell centres (nx, ny, 2) m, each cell's wall clearance
    (nx, ny) m, the free cells (nx, ny) bool and the weighted graph over them (scipy CSR, nx * ny nodes)."""

    centres: np.ndarray
    clear: np.ndarray
    free: np.ndarray
    graph: object


class GridCache:
    """What a route search among the same walls can reuse, the newest GRID_CACHE_SIZE of each kind: whole grids by
    (walls, lattice origin and size, settings), and wall-clearance fields by (walls, origin, cell), computed
    CLEARANCE_SLACK_CELLS beyond the size asked for, so that a robot straying out of the walls' box (which grows
    the grid) needs a new graph but not a new field. Exact keys (the bytes of the walls and of the origin); a cell's
    clearance does not depend on the size of the field it is computed in (tested), so a hit returns exactly what a
    new build would compute."""

    def __init__(self) -> None:
        self.grids: dict[tuple, RouteGrid] = {}
        self.fields: dict[tuple, np.ndarray] = {}

    @staticmethod
    def _keep(store: dict, key: tuple, value) -> None:
        store.pop(key, None)
        while len(store) >= GRID_CACHE_SIZE:
            store.pop(next(iter(store)))
        store[key] = value  # newest last

    def clearance(self, lo: np.ndarray, shape: tuple[int, int], walls: np.ndarray, cell_m: float) -> np.ndarray:
        """(nx, ny) wall clearance (m) of the cells lo + cell_m * (i, j)."""
        key = (lo.tobytes(), walls.tobytes(), cell_m)
        field = self.fields.get(key)
        if field is None or field.shape[0] < shape[0] or field.shape[1] < shape[1]:
            big = (shape[0] + CLEARANCE_SLACK_CELLS, shape[1] + CLEARANCE_SLACK_CELLS)
            if field is not None:
                big = (max(big[0], field.shape[0]), max(big[1], field.shape[1]))
            field = wall_clearance(_centres(lo, big, cell_m), walls)
            field.setflags(write=False)
            self._keep(self.fields, key, field)
        return field[: shape[0], : shape[1]]

    def grid(self, key: tuple, build) -> RouteGrid:
        grid = self.grids.get(key)
        if grid is None:
            grid = build()
            self._keep(self.grids, key, grid)
        return grid


def _centres(lo: np.ndarray, shape: tuple[int, int], cell_m: float) -> np.ndarray:
    """(nx, ny, 2) m: the cell centres lo + cell_m * (i, j)."""
    xs, ys = lo[0] + cell_m * np.arange(shape[0]), lo[1] + cell_m * np.arange(shape[1])
    return np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1)


def in_sight(start: np.ndarray, ends: np.ndarray, walls: np.ndarray, clearance_m: float, step_m: float) -> np.ndarray:
    """(E,) bool: the straight segments from start (2,) to each of ends (E, 2) keep clearance_m from every wall
    (checked at points at most step_m apart), or, from a start nearer a wall than that, come no nearer to any wall
    than the start is."""
    ends = np.atleast_2d(np.asarray(ends, float))
    if len(walls) == 0:
        return np.ones(len(ends), bool)
    n = max(2, int(np.ceil(np.linalg.norm(ends - start, axis=1).max(initial=0.0) / step_m)) + 1)
    s = np.linspace(0.0, 1.0, n)[None, :, None]
    pts = start + s * (ends[:, None, :] - start)  # (E, n, 2)
    need = min(clearance_m, float(wall_clearance(start, walls)) - 1e-9)
    return (wall_clearance(pts, walls) >= need).all(axis=1)


def grid_route(start: np.ndarray, goal: np.ndarray, walls: np.ndarray, cfg: RouteConfig,
               clearance_m: float, cache: GridCache | None = None) -> np.ndarray | None:
    """A shortest path (P, 2) m from start to goal through the free grid cells, those at least clearance_m from
    every wall (see the module docstring): from the start's cell to the goal's, with start and goal themselves as
    its ends; None when no path exists. A start or goal cell inside the walls' clearance is joined to its nearest
    free cell. ``cache`` keeps the grid for later searches among the same walls on the same lattice."""
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    pts = np.vstack([walls[:, :2], walls[:, 2:], start, goal]) if len(walls) else np.vstack([start, goal])
    lo, hi = pts.min(0) - cfg.padding_m, pts.max(0) + cfg.padding_m
    nx, ny = (np.ceil((hi - lo) / cfg.cell_m).astype(int) + 1)
    if nx * ny > cfg.max_cells:
        raise ValueError(f"route grid of {nx} x {ny} cells exceeds RouteConfig.max_cells={cfg.max_cells}; "
                         "raise cell_m")
    walls = np.ascontiguousarray(walls, float)
    shape = (int(nx), int(ny))

    def build() -> RouteGrid:
        centres = _centres(lo, shape, cfg.cell_m)
        clear = wall_clearance(centres, walls) if cache is None else cache.clearance(lo, shape, walls, cfg.cell_m)
        return _build_grid(centres, clear, cfg, clearance_m)

    key = (lo.tobytes(), shape, walls.tobytes(), cfg, float(clearance_m))
    grid = build() if cache is None else cache.grid(key, build)
    ends = [_nearest_free(p, lo, cfg.cell_m, grid.centres, grid.free) for p in (start, goal)]
    if ends[0] is None or ends[1] is None:
        return None
    from scipy.sparse.csgraph import dijkstra  # imported here: `import planner` stays numpy + casadi

    index = np.arange(nx * ny).reshape(nx, ny)
    src, dst = index[ends[0]], index[ends[1]]
    dist, pred = dijkstra(grid.graph, directed=False, indices=src, return_predecessors=True)
    if not np.isfinite(dist[dst]):
        return None
    cells = [dst]
    while cells[-1] != src:
        cells.append(pred[cells[-1]])
    path = grid.centres.reshape(-1, 2)[np.array(cells[::-1])]
    return np.vstack([start, path, goal])


def _build_grid(centres: np.ndarray, clear: np.ndarray, cfg: RouteConfig, clearance_m: float) -> RouteGrid:
    """The grid of cells ``centres`` (nx, ny, 2) m with wall clearances ``clear`` (nx, ny) m: free cells and the
    weighted graph."""
    free = clear >= clearance_m
    penalty = 1.0 + cfg.clearance_weight * np.clip(cfg.comfort_m - clear, 0.0, None) / cfg.comfort_m
    for a in (centres, free):
        a.setflags(write=False)  # shared by later searches
    return RouteGrid(centres, clear, free, _grid_graph(free, penalty, cfg.cell_m))


def _nearest_free(p: np.ndarray, lo: np.ndarray, cell_m: float, centres: np.ndarray,
                  free: np.ndarray) -> tuple[int, int] | None:
    """The grid index of p's cell if free, else of the nearest free cell; None without free cells."""
    i, j = np.clip(np.rint((p - lo) / cell_m).astype(int), 0, np.array(free.shape) - 1)
    if free[i, j]:
        return int(i), int(j)
    if not free.any():
        return None
    d = np.where(free, np.linalg.norm(centres - p, axis=-1), np.inf)
    return tuple(int(v) for v in np.unravel_index(np.argmin(d), d.shape))


def _grid_graph(free: np.ndarray, penalty: np.ndarray, cell_m: float):
    """Sparse undirected graph over the grid: free neighbours joined by length * mean penalty of the two cells."""
    from scipy.sparse import coo_matrix

    nx, ny = free.shape
    index = np.arange(nx * ny).reshape(nx, ny)
    rows, cols, weights = [], [], []
    for di, dj in NEIGHBOURS:
        a = (slice(0, nx - di), slice(max(0, -dj), ny - max(0, dj)))
        b = (slice(di, nx), slice(max(0, dj), ny - max(0, -dj)))
        both = free[a] & free[b]
        rows.append(index[a][both])
        cols.append(index[b][both])
        weights.append(cell_m * np.hypot(di, dj) * 0.5 * (penalty[a][both] + penalty[b][both]))
    return coo_matrix((np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(nx * ny, nx * ny)).tocsr()


class Router:
    """Subgoals for a local planner (see the module docstring). Keeps the last route; `reset()` forgets it."""

    def __init__(self, config: RouteConfig, clearance_m: float) -> None:
        if not (np.isfinite(clearance_m) and clearance_m >= 0):
            raise ValueError(f"clearance_m must be >= 0 m, got {clearance_m!r}")
        self.config, self.clearance_m = config, float(clearance_m)
        self._key: tuple | None = None
        self._path: np.ndarray | None = None  # (P, 2) m
        self._arc: np.ndarray | None = None  # (P,) m, arc length along the path
        self._failed_at: np.ndarray | None = None  # (2,) m, where the last search for this key found no route
        self.grids = GridCache()  # kept through reset(): keyed by the walls themselves

    def reset(self) -> None:
        self._key, self._path, self._arc, self._failed_at = None, None, None, None

    def subgoal(self, position: np.ndarray, goal: np.ndarray, walls: np.ndarray | None) -> np.ndarray:
        """The point (2,) m the local planner should head for, from the robot's position (2,) m to goal (2,) m among
        walls (W, 4) m (None: none). The goal itself when it is in sight or no route exists."""
        position, goal = np.asarray(position, float), np.asarray(goal, float)
        walls = np.zeros((0, 4)) if walls is None else np.asarray(walls, float).reshape(-1, 4)
        cfg = self.config
        if in_sight(position, goal[None], walls, self.clearance_m, 0.5 * cfg.cell_m)[0]:
            return goal
        key = (goal.tobytes(), walls.tobytes())
        if key == self._key and self._failed_at is not None and \
                np.linalg.norm(position - self._failed_at) <= cfg.replan_distance_m:
            return goal  # no route from here a moment ago: search again only once the robot has moved on
        near = self._nearest(position) if key == self._key else None
        if near is None or np.linalg.norm(self._path[near] - position) > cfg.replan_distance_m:
            self._key, self._path = key, grid_route(position, goal, walls, cfg, self.clearance_m, self.grids)
            self._failed_at = None if self._path is not None else position.copy()
            if self._path is None:
                return goal
            self._arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(self._path, axis=0), axis=1))]
            near = self._nearest(position)
        return self._carrot(position, near, walls)

    def _nearest(self, position: np.ndarray) -> int | None:
        if self._path is None:
            return None
        return int(np.argmin(np.linalg.norm(self._path - position, axis=1)))

    def _carrot(self, position: np.ndarray, near: int, walls: np.ndarray) -> np.ndarray:
        cfg, path, arc = self.config, self._path, self._arc
        ahead = np.flatnonzero((arc >= arc[near]) & (arc <= arc[near] + cfg.lookahead_m))
        seen = ahead[in_sight(position, path[ahead], walls, self.clearance_m, 0.5 * cfg.cell_m)]
        last = int(seen.max()) if seen.size else min(near + 1, len(path) - 1)
        carrot = path[last]
        short = cfg.lookahead_m - np.linalg.norm(carrot - position)
        if short > 0 and last < len(path) - 1:  # slide on along the path so that the robot need not brake
            on = np.flatnonzero(arc >= arc[last] + short)
            carrot = path[on[0]] if on.size else path[-1]
        return carrot
