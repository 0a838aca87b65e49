"""Pedestrian prediction input of the planner, its validation, and constant-velocity / frozen helpers.

The planner takes plain arrays bundled in :class:`PedPrediction` (never predictor objects):

============  ==============  =====================================================================
field         shape           meaning
============  ==============  =====================================================================
positions     (K, T, N, 2)    absolute predicted positions (m) at +step_s, +2 step_s, ... +T step_s
radii         (N,)            body radius (m)
group_ids     (N,) int        group label; a pedestrian alone is its own group of one
mask          (N,) bool       True where the pedestrian is real; False rows are padding and ignored
current       (N, 2) or None  positions now (m); if None, extrapolated back from the first two steps
history       (T_obs, N, 2)   optional observed positions, oldest first, last row = now (baselines)
step_s        float           time between prediction steps (s); required: the planner assumes none
============  ==============  =====================================================================

Values of masked-out pedestrians may be anything, NaN included. Non-finite values of real
pedestrians, or wrong shapes, raise ``ValueError`` when :func:`validate_prediction` runs (the
planner calls it before building any solver input).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class PedPrediction:
    """Predicted pedestrian positions and attributes as arrays; see the module docstring for shapes."""

    positions: np.ndarray
    radii: np.ndarray
    group_ids: np.ndarray
    mask: np.ndarray
    current: np.ndarray | None = None
    history: np.ndarray | None = None
    step_s: float = field(kw_only=True)  # the predictor's step, s (ETH/UCY: 0.4); never assumed here

    def __post_init__(self) -> None:
        validate_prediction(self)

    @property
    def n_peds(self) -> int:
        """N, the number of pedestrian rows (real and padding)."""
        return int(np.shape(self.positions)[2])


def _fail(msg: str) -> None:
    raise ValueError(f"invalid PedPrediction: {msg}")


def _check_finite(name: str, arr: np.ndarray, mask: np.ndarray, ped_axis: int) -> None:
    real = np.compress(mask, arr, axis=ped_axis)
    if not np.all(np.isfinite(real)):
        _fail(f"{name} has NaN or inf values for real (mask=True) pedestrians")


def validate_prediction(pred: PedPrediction) -> None:
    """Raise ValueError with a clear message if shapes, dtypes or values of ``pred`` are invalid."""
    pos = np.asarray(pred.positions)
    if pos.ndim != 4 or pos.shape[3] != 2 or pos.shape[0] < 1 or pos.shape[1] < 1:
        _fail(f"positions must have shape (K>=1, T>=1, N, 2), got {pos.shape}")
    n = pos.shape[2]
    for name in ("radii", "group_ids", "mask"):
        if np.shape(getattr(pred, name)) != (n,):
            _fail(f"{name} must have shape ({n},), got {np.shape(getattr(pred, name))}")
    mask = np.asarray(pred.mask)
    if mask.dtype != bool:
        _fail(f"mask must be bool, got dtype {mask.dtype}")
    if not np.issubdtype(np.asarray(pred.group_ids).dtype, np.integer):
        _fail(f"group_ids must be integers, got dtype {np.asarray(pred.group_ids).dtype}")
    if not (np.isfinite(pred.step_s) and pred.step_s > 0):
        _fail(f"step_s must be a finite number > 0, got {pred.step_s!r}")
    _check_finite("positions", pos, mask, 2)
    radii = np.asarray(pred.radii, float)
    _check_finite("radii", radii, mask, 0)
    if np.any(radii[mask] < 0):
        _fail("radii must be >= 0")
    if pred.current is not None:
        if np.shape(pred.current) != (n, 2):
            _fail(f"current must have shape ({n}, 2), got {np.shape(pred.current)}")
        _check_finite("current", np.asarray(pred.current, float), mask, 0)
    if pred.history is not None:
        hist = np.asarray(pred.history)
        if hist.ndim != 3 or hist.shape[1:] != (n, 2) or hist.shape[0] < 1:
            _fail(f"history must have shape (T_obs>=1, {n}, 2), got {hist.shape}")
        _check_finite("history", hist.astype(float), mask, 1)


def empty_prediction(n_steps: int, step_s: float) -> PedPrediction:
    """A prediction with no pedestrians (K=1, T=n_steps, N=0)."""
    return PedPrediction(np.zeros((1, n_steps, 0, 2)), np.zeros(0), np.zeros(0, int), np.zeros(0, bool),
                         current=np.zeros((0, 2)), step_s=step_s)


def current_positions(pred: PedPrediction) -> np.ndarray:
    """Positions now (N, 2): ``current``, else ``history[-1]``, else extrapolated back from the
    sample mean of the first two prediction steps (or the first step when T == 1)."""
    if pred.current is not None:
        return np.asarray(pred.current, float)
    if pred.history is not None:
        return np.asarray(pred.history, float)[-1]
    pos = np.asarray(pred.positions, float)
    if pos.shape[1] == 1:
        return pos[:, 0].mean(axis=0)
    return (2.0 * pos[:, 0] - pos[:, 1]).mean(axis=0)


def _defaults(n: int, radii, group_ids, mask) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    radii = np.full(n, 0.3) if radii is None else np.asarray(radii, float)
    group_ids = np.arange(n) if group_ids is None else np.asarray(group_ids)
    mask = np.ones(n, bool) if mask is None else np.asarray(mask, bool)
    return radii, group_ids, mask


def constant_velocity_prediction(history: np.ndarray, radii: np.ndarray | None = None,
                                 group_ids: np.ndarray | None = None, mask: np.ndarray | None = None,
                                 *, n_steps: int, step_s: float) -> PedPrediction:
    """Constant-velocity prediction (K=1) from observed positions ``history`` (T_obs, N, 2), rows
    ``step_s`` apart, last row = now. The velocity is the last displacement / step_s (zero if
    T_obs == 1). Defaults: radii 0.3 m, every pedestrian its own group, all real."""
    hist = np.asarray(history, float)
    n = hist.shape[1] if hist.ndim == 3 else -1
    radii, group_ids, mask = _defaults(max(n, 0), radii, group_ids, mask)
    if hist.ndim != 3 or hist.shape[2] != 2:
        _fail(f"history must have shape (T_obs, N, 2), got {hist.shape}")
    now = hist[-1]
    vel = (hist[-1] - hist[-2]) / step_s if hist.shape[0] >= 2 else np.zeros_like(now)
    times = step_s * np.arange(1, n_steps + 1)
    positions = (now[None] + times[:, None, None] * vel[None])[None]
    return PedPrediction(positions, radii, group_ids, mask, current=now, history=hist, step_s=step_s)


def frozen_prediction(current: np.ndarray, radii: np.ndarray | None = None,
                      group_ids: np.ndarray | None = None, mask: np.ndarray | None = None,
                      *, n_steps: int, step_s: float) -> PedPrediction:
    """Pedestrians frozen at ``current`` (N, 2) for n_steps steps (K=1)."""
    now = np.asarray(current, float)
    radii, group_ids, mask = _defaults(now.shape[0], radii, group_ids, mask)
    positions = np.broadcast_to(now, (1, n_steps, *now.shape)).copy()
    return PedPrediction(positions, radii, group_ids, mask, current=now, step_s=step_s)
