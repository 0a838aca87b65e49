"""Scenario files: a scene (walls, flows, stop areas, ...) as a small TOML file, read with `tomllib`.

The six built-in scenarios are such files (`crowdsim/builtin_scenarios/*.toml`); `crowdsim.scenarios.make_scenario`
reads a built-in by name or any file by its path (ending in `.toml`). The format, in full (docs/crowdsim.md has a
complete example):

    name = "my_room"                 # required
    description = "one line"
    bounds = [xmin, ymin, xmax, ymax]  # required, m
    on_arrival = "remove"            # remove | stop | new_goal
    continuous = true                # keep the crowd size by spawning (a bool, or a condition string)
    exit_radius_m = 1.0
    periodic_x = [x0, x1]            # optional; also dense_spawn, interior (rectangles)
    stop_areas = [rect, ...]         # rectangles where groups may stop
    pois = [[x, y], ...]             # points of interest
    [options]                        # name = default (a number; true/false makes a 0/1 flag); units in the names
    [let]                            # derived values, computed in order from the options and earlier lets
    [[walls]]                        # segments = [[[x, y], [x, y]], ...], or polygon = [[x, y], ...] (closed;
                                     # open = true: a polyline)
    [[flows]]                        # spawn = rect, target = rect
    [[gates]]                        # spawn = rect, target = rect: a flow from each gate to every other gate
    [[rings]]                        # count, radius, spawn_half_m, target_half_m: flows across a circle
    [robot]                          # start = rect, goal = rect, both_ways = false: the robot's route (envs)

A rectangle is [xmin, ymin, xmax, ymax] in metres. Every number may be a string holding arithmetic over the option
and let names: numbers, names, + - * /, unary minus, parentheses, min(...) and max(...). A `[[walls]]`,
`[[flows]]`, `[[gates]]` or `[[rings]]` table may carry `when = "CONDITION"` (it exists only when the condition
holds), and a rectangle, point or range may be written `{ when = "CONDITION", value = ... }`; conditions add
comparisons (< <= > >= == !=) and `and`, `or`, `not`. The flows are those of `[[flows]]`, then each ordered pair
of distinct gates, then the rings, in file order.

A bad file raises `ScenarioFileError` (a ValueError): one line naming the file, the key and what was expected.
"""

from __future__ import annotations

import ast
import hashlib
import itertools
import math
import operator
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from crowdsim.names import did_you_mean

Rect = tuple[float, float, float, float]  # xmin, ymin, xmax, ymax in metres

TOP_KEYS = ("name", "description", "bounds", "on_arrival", "continuous", "exit_radius_m", "periodic_x",
            "dense_spawn", "interior", "stop_areas", "pois", "options", "let", "walls", "flows", "gates", "rings",
            "robot")
TABLE_KEYS = {
    "walls": ("segments", "polygon", "open", "when"),
    "flows": ("spawn", "target", "when"),
    "gates": ("spawn", "target", "when"),
    "rings": ("count", "radius", "spawn_half_m", "target_half_m", "when"),
    "robot": ("start", "goal", "both_ways"),
}
_ARITH: dict[type, Callable[[float, float], float]] = {
    ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv}
_COMPARE: dict[type, Callable[[float, float], bool]] = {
    ast.Lt: operator.lt, ast.LtE: operator.le, ast.Gt: operator.gt, ast.GtE: operator.ge, ast.Eq: operator.eq,
    ast.NotEq: operator.ne}
_FUNCTIONS: dict[str, Callable[..., float]] = {"min": min, "max": max}


class ScenarioFileError(ValueError):
    """A scenario file that cannot be read: the message is one line naming the file and the key."""


class _Reader:
    """Reads the values of one file under one set of option values; errors name the file and the key."""

    def __init__(self, source: str, names: Mapping[str, float]) -> None:
        self.source = source
        self.names = dict(names)

    def fail(self, key: str, message: str) -> ScenarioFileError:
        return ScenarioFileError(f"{self.source}: {key}: {message}")

    # --- expressions -------------------------------------------------------------------------------------------
    def number(self, key: str, value: Any) -> float:
        """A number or an arithmetic string, as a float."""
        if isinstance(value, bool) or not isinstance(value, int | float | str):
            raise self.fail(key, f"expected a number or an expression string, got {value!r}")
        if isinstance(value, str):
            value = self._eval(key, value, self._parse(key, value), condition=False)
        out = float(value)
        if not math.isfinite(out):
            raise self.fail(key, f"expected a finite number, got {out!r}")
        return out

    def condition(self, key: str, value: Any) -> bool:
        """A bool or a condition string."""
        if isinstance(value, bool):
            return value
        if not isinstance(value, str):
            raise self.fail(key, f"expected true, false or a condition string, got {value!r}")
        return bool(self._eval(key, value, self._parse(key, value), condition=True))

    def _parse(self, key: str, text: str) -> ast.expr:
        try:
            return ast.parse(text.strip(), mode="eval").body
        except SyntaxError:
            raise self.fail(key, f"cannot parse the expression {text!r}") from None

    def _eval(self, key: str, text: str, node: ast.expr, condition: bool) -> Any:
        ev = lambda n: self._eval(key, text, n, condition)  # noqa: E731
        if isinstance(node, ast.Constant) and isinstance(node.value, int | float) and not isinstance(node.value, bool):
            return node.value
        if isinstance(node, ast.Name):
            if node.id not in self.names:
                raise self.fail(key, f"unknown name {node.id!r} in {text!r};{did_you_mean(node.id, self.names)} "
                                     f"known names: {', '.join(self.names) or '(none)'}")
            return self.names[node.id]
        if isinstance(node, ast.BinOp) and type(node.op) in _ARITH:
            left, right = ev(node.left), ev(node.right)
            if isinstance(node.op, ast.Div) and right == 0:
                raise self.fail(key, f"division by zero in {text!r}")
            return _ARITH[type(node.op)](left, right)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
            return -ev(node.operand) if isinstance(node.op, ast.USub) else +ev(node.operand)
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FUNCTIONS
                and node.args and not node.keywords):
            return _FUNCTIONS[node.func.id](*(ev(a) for a in node.args))
        if condition and isinstance(node, ast.Compare):
            left = ev(node.left)
            for op, right_node in zip(node.ops, node.comparators, strict=True):
                right = ev(right_node)
                if type(op) not in _COMPARE:
                    break
                if not _COMPARE[type(op)](left, right):
                    return False
                left = right
            else:
                return True
        if condition and isinstance(node, ast.BoolOp):
            values = (ev(v) for v in node.values)
            return all(values) if isinstance(node.op, ast.And) else any(values)
        if condition and isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
            return not ev(node.operand)
        allowed = ("numbers, names, + - * /, unary minus, parentheses, min(), max()"
                   + (", comparisons, and, or, not" if condition else ""))
        raise self.fail(key, f"{ast.unparse(node)!r} is not allowed in {text!r}; allowed: {allowed}")

    # --- shapes ------------------------------------------------------------------------------------------------
    def unwrap(self, key: str, value: Any) -> Any | None:
        """A value written `{when = ..., value = ...}`: its value, or None when the condition fails."""
        if not isinstance(value, dict):
            return value
        self.keys(key, value, ("when", "value"), required=("value",))
        return value["value"] if self.condition(f"{key}.when", value.get("when", True)) else None

    def vector(self, key: str, value: Any, n: int, what: str) -> tuple[float, ...]:
        if not isinstance(value, list) or len(value) != n:
            raise self.fail(key, f"expected {what}, got {value!r}")
        return tuple(self.number(f"{key}[{i}]", v) for i, v in enumerate(value))

    def rect(self, key: str, value: Any) -> Rect:
        out = self.vector(key, value, 4, "a rectangle [xmin, ymin, xmax, ymax]")
        if out[0] > out[2] or out[1] > out[3]:
            raise self.fail(key, f"expected a rectangle [xmin, ymin, xmax, ymax] with xmin <= xmax and ymin <= ymax, "
                                 f"got {list(out)}")
        return out  # type: ignore[return-value]

    def point(self, key: str, value: Any) -> tuple[float, float]:
        return self.vector(key, value, 2, "a point [x, y]")  # type: ignore[return-value]

    def keys(self, key: str, table: Any, valid: tuple[str, ...], required: tuple[str, ...] = ()) -> dict[str, Any]:
        if not isinstance(table, dict):
            raise self.fail(key, f"expected a table with keys {', '.join(valid)}, got {table!r}")
        for k in table:
            if k not in valid:
                raise self.fail(f"{key}.{k}" if key else k, f"unknown key;{did_you_mean(k, valid)} valid keys: "
                                                            f"{', '.join(valid)}")
        for k in required:
            if k not in table:
                raise self.fail(f"{key}.{k}" if key else k, "missing (required)")
        return table

    def tables(self, key: str, value: Any) -> list[tuple[str, dict[str, Any]]]:
        """The tables of an array of tables that exist (their `when` holds), with their keys for messages."""
        if not isinstance(value, list):
            raise self.fail(key, f"expected an array of tables ([[{key}]]), got {value!r}")
        out = []
        for i, table in enumerate(value):
            k = f"{key}[{i}]"
            self.keys(k, table, TABLE_KEYS[key])
            if self.condition(f"{k}.when", table.get("when", True)):
                out.append((k, table))
        return out

    def walls(self, value: Any) -> list[list[tuple[float, float]]]:
        segments: list[list[tuple[float, float]]] = []
        for k, table in self.tables("walls", value):
            shapes = [s for s in ("segments", "polygon") if s in table]
            if len(shapes) != 1:
                raise self.fail(k, "expected exactly one of segments or polygon")
            if "segments" in table:
                if "open" in table:
                    raise self.fail(f"{k}.open", "applies to a polygon only")
                if not isinstance(table["segments"], list):
                    raise self.fail(f"{k}.segments", "expected an array of segments [[x, y], [x, y]]")
                for i, seg in enumerate(table["segments"]):
                    if not isinstance(seg, list) or len(seg) != 2:
                        raise self.fail(f"{k}.segments[{i}]", f"expected a segment [[x, y], [x, y]], got {seg!r}")
                    segments.append([self.point(f"{k}.segments[{i}][{j}]", p) for j, p in enumerate(seg)])
                continue
            is_open = table.get("open", False)
            if not isinstance(is_open, bool):
                raise self.fail(f"{k}.open", f"expected true or false, got {is_open!r}")
            points = table["polygon"]
            least = 2 if is_open else 3
            if not isinstance(points, list) or len(points) < least:
                raise self.fail(f"{k}.polygon", f"expected at least {least} points [x, y] "
                                                f"({'a polyline' if is_open else 'a closed polygon'}), got {points!r}")
            pts = [self.point(f"{k}.polygon[{j}]", p) for j, p in enumerate(points)]
            ring = pts if is_open else [*pts, pts[0]]
            segments += [[a, b] for a, b in itertools.pairwise(ring)]
        return segments

    def flows(self, doc: dict[str, Any]) -> list[tuple[Rect, Rect]]:
        out = []
        for k, table in self.tables("flows", doc.get("flows", [])):
            self.keys(k, table, TABLE_KEYS["flows"], required=("spawn", "target"))
            out.append((self.rect(f"{k}.spawn", table["spawn"]), self.rect(f"{k}.target", table["target"])))
        gates = []
        for k, table in self.tables("gates", doc.get("gates", [])):
            self.keys(k, table, TABLE_KEYS["gates"], required=("spawn", "target"))
            gates.append((self.rect(f"{k}.spawn", table["spawn"]), self.rect(f"{k}.target", table["target"])))
        out += [(gates[a][0], gates[b][1]) for a in range(len(gates)) for b in range(len(gates)) if a != b]
        for k, table in self.tables("rings", doc.get("rings", [])):
            self.keys(k, table, TABLE_KEYS["rings"], required=("count", "radius", "spawn_half_m", "target_half_m"))
            count = table["count"]
            if isinstance(count, bool) or not isinstance(count, int) or count < 1:
                raise self.fail(f"{k}.count", f"expected an integer >= 1, got {count!r}")
            r = self.number(f"{k}.radius", table["radius"])
            hs, ht = (self.number(f"{k}.{h}", table[h]) for h in ("spawn_half_m", "target_half_m"))
            for i in range(count):  # a spawn square on the circle, the target square at the opposite point
                a = 2 * np.pi * i / count
                c, s = np.cos(a), np.sin(a)
                p, q = (float(r * c), float(r * s)), (float(-r * c), float(-r * s))
                out.append(((p[0] - hs, p[1] - hs, p[0] + hs, p[1] + hs), (q[0] - ht, q[1] - ht, q[0] + ht, q[1] + ht)))
        return out


@dataclass(frozen=True)
class ScenarioFile:
    """One scenario file, parsed: its `[options]` defaults (flags are those given as true/false) and its text.

    `fields(options)` evaluates it under the given option values (defaults for the others): the keyword arguments
    of `crowdsim.scenarios.Scenario`, flows as (spawn, target) rectangle pairs, plus `robot_start`/`robot_goal`.
    """

    source: str  # the path as given (messages name it)
    name: str
    description: str
    options: dict[str, float]
    flags: tuple[str, ...]
    doc: dict[str, Any]
    sha256: str  # of the file's bytes

    def fields(self, options: Mapping[str, float]) -> dict[str, Any]:
        values = {**self.options, **{k: float(v) for k, v in options.items()}}
        r = _Reader(self.source, values)
        doc = self.doc
        for k, expr in doc.get("let", {}).items():
            r.names[k] = r.number(f"let.{k}", expr)
        out: dict[str, Any] = {"name": self.name, "walls": np.array(r.walls(doc.get("walls", [])), dtype=float)
                               .reshape(-1, 2, 2), "bounds": r.rect("bounds", doc["bounds"]), "flows": r.flows(doc)}
        if not out["flows"]:
            raise r.fail("flows", "expected at least one flow ([[flows]], [[gates]] or [[rings]])")
        if "on_arrival" in doc:
            out["on_arrival"] = doc["on_arrival"]
            if out["on_arrival"] not in ("remove", "stop", "new_goal"):
                raise r.fail("on_arrival", f"expected remove, stop or new_goal, got {doc['on_arrival']!r}")
        if "continuous" in doc:
            out["continuous"] = r.condition("continuous", doc["continuous"])
        if "exit_radius_m" in doc:
            out["exit_radius_m"] = r.number("exit_radius_m", doc["exit_radius_m"])
        periodic = r.unwrap("periodic_x", doc.get("periodic_x"))
        if periodic is not None:
            out["periodic_x"] = r.vector("periodic_x", periodic, 2, "a range [x0, x1]")
        for key in ("dense_spawn", "interior"):
            rect = r.unwrap(key, doc.get(key))
            if rect is not None:
                out[key] = r.rect(key, rect)
        for key, read in (("stop_areas", r.rect), ("pois", r.point)):
            items = doc.get(key, [])
            if not isinstance(items, list):
                raise r.fail(key, f"expected an array, got {items!r}")
            kept = ((f"{key}[{i}]", r.unwrap(f"{key}[{i}]", v)) for i, v in enumerate(items))
            out[key] = tuple(read(k, v) for k, v in kept if v is not None)
        robot = r.keys("robot", doc.get("robot", {}), TABLE_KEYS["robot"])
        if robot:
            r.keys("robot", robot, TABLE_KEYS["robot"], required=("start", "goal"))
            out["robot_start"], out["robot_goal"] = r.rect("robot.start", robot["start"]), r.rect("robot.goal",
                                                                                                  robot["goal"])
            both = robot.get("both_ways", False)
            if not isinstance(both, bool):
                raise r.fail("robot.both_ways", f"expected true or false, got {both!r}")
            out["robot_both_ways"] = both
        return out


def parse_scenario(text: bytes, source: str) -> ScenarioFile:
    """Parse the bytes of a scenario file (`source` names it in messages); checks everything but the values."""
    try:
        doc = tomllib.loads(text.decode("utf-8"))
    except UnicodeDecodeError:
        raise ScenarioFileError(f"{source}: not a UTF-8 text file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioFileError(f"{source}: malformed TOML: {exc}") from None
    r = _Reader(source, {})
    r.keys("", doc, TOP_KEYS, required=("name", "bounds"))
    for key in ("name", "description"):
        if not isinstance(doc.get(key, ""), str):
            raise r.fail(key, f"expected a string, got {doc[key]!r}")
    if not doc["name"].strip():
        raise r.fail("name", "expected a non-empty string")
    options = doc.get("options", {})
    if not isinstance(options, dict):
        raise r.fail("options", f"expected a table of name = default, got {options!r}")
    defaults: dict[str, float] = {}
    for k, v in options.items():
        if not k.isidentifier() or k in _FUNCTIONS:
            raise r.fail(f"options.{k}", "expected a name of letters, digits and underscores (not min or max)")
        if isinstance(v, str):
            raise r.fail(f"options.{k}", f"expected a number or true/false (a default, not an expression), got {v!r}")
        defaults[k] = float(v) if isinstance(v, bool) else r.number(f"options.{k}", v)
    let = doc.get("let", {})
    if not isinstance(let, dict):
        raise r.fail("let", f"expected a table of name = expression, got {let!r}")
    for k in let:
        if k in defaults or not k.isidentifier() or k in _FUNCTIONS:
            raise r.fail(f"let.{k}", "expected a new name (not an option's, min or max)")
    for key in ("walls", "flows", "gates", "rings"):
        if key in doc and not (isinstance(doc[key], list) and all(isinstance(t, dict) for t in doc[key])):
            raise r.fail(key, f"expected an array of tables ([[{key}]])")
    flags = tuple(k for k, v in options.items() if isinstance(v, bool))
    return ScenarioFile(source, doc["name"], str(doc.get("description", "")), defaults, flags, doc,
                        hashlib.sha256(text).hexdigest())


def read_scenario_file(path: str | Path) -> ScenarioFile:
    """Read and parse a scenario file, then build it once with its defaults, so that a bad file fails here."""
    try:
        text = Path(path).read_bytes()
    except OSError as exc:
        raise ScenarioFileError(f"{path}: cannot read the scenario file: {(exc.strerror or str(exc)).lower()}") \
            from None
    parsed = parse_scenario(text, str(path))
    parsed.fields({})
    return parsed
