"""How wrong the observed predictions have been so far in the episode: a running conformal calibration per person.

On every 0.4 s planning tick the env hands `PredictionCalibration.update` the people the predictor ran on (their
ids and true positions now) and the predictions just made for them, samples (K, 12, n, 2) m at +0.4 ... +4.8 s.
The predictions of the last 12 ticks are kept; a prediction made h ticks ago has its step h come due now, and for
every person it covered who is observed now the displacement error of that step is recorded:

    e = min over the K samples of |predicted position at step h - true position now|, m.

The minimum over samples (not the error of the sample mean) because the observation shows the agent the samples
themselves: q_h from the errors below bounds the distance from the person to the nearest of their K observed points,
so the union of the discs of radius q_h around the samples is a conformal prediction set for where they will be,
whatever the spread of the samples (the mean of a two-way split may lie where nobody walks). With one sample (the
constant-velocity predictor, the oracle) both choices agree.

Each person (by ped_id: one who leaves and comes back keeps their record) keeps the last `window` errors of each
of the 12 steps. The calibration of step h is the conformal quantile of those n errors at 1 - alpha with the
finite-sample correction: the empirical quantile at level ceil((n + 1)(1 - alpha)) / n, i.e. the k-th smallest
error with k = ceil((n + 1)(1 - alpha)) (`conformal_quantile`). When k > n (fewer than (1 - alpha) / alpha errors,
9 at alpha 0.1) the level is capped at 1, so the largest error seen is given instead of infinity; with no error yet
the value is the prior, 0 m, and `counts` (how many step-1 errors the window holds, 0..window) tells the two apart:
a person tracked since c ticks ago has min(c, window) step-1 errors and, at step h, min(max(c - h + 1, 0), window).

State lives in `PredictionCalibration` (reset with the episode); pure numpy, vectorised over people and steps.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from envs.config import ObservationConfig

PRIOR_ERROR_M = 0.0  # the calibration of a step with no matured error yet (see `counts`)


def conformal_quantile(errors: np.ndarray, n: np.ndarray, alpha: float) -> np.ndarray:
    """The conformal (1 - alpha) quantile of each row of errors (..., W) m whose first n (...) entries after sorting
    are the recorded errors (the rest NaN): the k-th smallest with k = ceil((n + 1)(1 - alpha)) capped at n (the
    empirical quantile at level min(1, ceil((n + 1)(1 - alpha)) / n), numpy's 'inverted_cdf'); `PRIOR_ERROR_M` where
    n is 0. (...) m. A 1e-9 slack keeps (n + 1)(1 - alpha) that is a whole number up to rounding from stepping up."""
    n = np.asarray(n, np.int64)
    ordered = np.sort(errors, axis=-1)  # NaN (empty slots) last
    k = np.ceil((n + 1) * (1.0 - alpha) - 1e-9).astype(np.int64)
    k = np.clip(k, 1, np.maximum(n, 1))
    q = np.take_along_axis(ordered, (k - 1)[..., None], axis=-1)[..., 0]
    return np.where(n > 0, q, PRIOR_ERROR_M)


def nearest_errors(points: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Displacement errors (n,) m of predicted points (n, K, 2) m against the true positions truth (n, 2) m: the
    distance to the nearest of the K points (NaN points, padding, ignored; NaN where all are)."""
    d = points - truth[:, None]
    return np.fmin.reduce(np.sqrt((d * d).sum(-1)), axis=1)


@dataclass
class PredictionCalibration:
    """The running calibration of one episode (module docstring). alpha in (0, 1); window: errors kept per person
    and step; pred_len: the prediction's steps T (12).

    The predictions waiting for their steps are one flat table (E entries: a person predicted on a tick), so that a
    tick scores them all at once: `_pend_rows` (E,) the person's row, `_pend_made` (E,) the tick it was made on,
    `_pend_points` (E, T, K, 2) m its samples (NaN where a tick had fewer than K). Per person (row, by ped_id):
    `_errors` (M, T, window) m, a ring of the last errors of each step (NaN in empty slots), `_count` (M, T) the
    errors ever recorded, and `_quantile` (M, T) m, their `conformal_quantile` (recomputed for the people scored)."""

    alpha: float
    window: int
    pred_len: int = 12
    _row: dict[int, int] = field(default_factory=dict)  # ped_id -> row
    _errors: np.ndarray = field(init=False)
    _count: np.ndarray = field(init=False)
    _quantile: np.ndarray = field(init=False)
    _pend_rows: np.ndarray = field(init=False)
    _pend_made: np.ndarray = field(init=False)
    _pend_points: np.ndarray = field(init=False)
    _shown: tuple = (None, None)  # (ids (n,) bytes, `features`) since the last update: asked again between ticks

    def __post_init__(self) -> None:
        if not 0.0 < self.alpha < 1.0:
            raise ValueError(f"alpha must be in (0, 1), got {self.alpha!r}")
        if not isinstance(self.window, int) or self.window < 1:
            raise ValueError(f"window must be an integer >= 1, got {self.window!r}")
        self.reset()

    def reset(self) -> None:
        """Forget everything (a new episode)."""
        t = self.pred_len
        self._row = {}
        self._errors = np.full((0, t, self.window), np.nan)
        self._count = np.zeros((0, t), np.int64)
        self._quantile = np.zeros((0, t))
        self._pend_rows, self._pend_made = np.zeros(0, np.int64), np.zeros(0, np.int64)
        self._pend_points = np.zeros((0, t, 1, 2))
        self._shown = (None, None)

    def update(self, tick: int, ids: np.ndarray, pos: np.ndarray, samples: np.ndarray | None) -> None:
        """On planning tick `tick` (0.4 s apart): score the steps of earlier predictions that come due now against
        the true positions pos (n, 2) m of the people ids (n,), drop the predictions whose last step has come, and
        keep this tick's samples (K, T, n, 2) m of the same people (None: nothing predicted)."""
        rows = self._rows(np.asarray(ids, np.int64))
        scored = self._score(tick, rows, np.asarray(pos, float))
        keep = tick - self._pend_made < self.pred_len
        self._pend_rows, self._pend_made, self._pend_points = \
            self._pend_rows[keep], self._pend_made[keep], self._pend_points[keep]
        if samples is not None and len(rows) and samples.shape[2] == len(rows):
            self._remember(tick, rows, np.asarray(samples, float))
        self._shown = (None, None)
        self._quantile[scored] = conformal_quantile(self._errors[scored], np.minimum(self._count[scored], self.window),
                                                    self.alpha)

    def _score(self, tick: int, rows: np.ndarray, pos: np.ndarray) -> np.ndarray:
        """Record the error of every waiting prediction whose step comes due on `tick` for a person observed now
        (rows (n,) at pos (n, 2) m); the rows whose errors changed."""
        here = np.full(len(self._count), -1, np.int64)
        here[rows] = np.arange(len(rows))
        lag = tick - self._pend_made  # the step (1..T) that comes due now
        at = here[self._pend_rows]
        due = np.flatnonzero((lag >= 1) & (lag <= self.pred_len) & (at >= 0))
        err = nearest_errors(self._pend_points[due, lag[due] - 1], pos[at[due]])
        ok = np.isfinite(err)
        r, step = self._pend_rows[due][ok], lag[due][ok] - 1  # distinct (person, step) pairs: one entry per tick
        self._errors[r, step, self._count[r, step] % self.window] = err[ok]
        self._count[r, step] += 1
        return np.unique(r)

    def _remember(self, tick: int, rows: np.ndarray, samples: np.ndarray) -> None:
        """Add the samples (K, T, n, 2) m made on `tick` for the people of rows (n,) to the waiting predictions."""
        points = samples.transpose(2, 1, 0, 3)  # (n, T, K, 2)
        k = max(points.shape[2], self._pend_points.shape[2])
        self._pend_points = np.concatenate([_pad_samples(self._pend_points, k), _pad_samples(points, k)])
        self._pend_rows = np.concatenate([self._pend_rows, rows])
        self._pend_made = np.concatenate([self._pend_made, np.full(len(rows), tick, np.int64)])

    def _rows(self, ids: np.ndarray) -> np.ndarray:
        """The rows (n,) of people ids (n,), new people given fresh empty rows."""
        new = [int(i) for i in ids if int(i) not in self._row]
        if new:
            at, t = len(self._count), self.pred_len
            self._row.update({pid: at + k for k, pid in enumerate(new)})
            self._errors = np.concatenate([self._errors, np.full((len(new), t, self.window), np.nan)])
            self._count = np.concatenate([self._count, np.zeros((len(new), t), np.int64)])
            self._quantile = np.concatenate([self._quantile, np.full((len(new), t), PRIOR_ERROR_M)])
        return np.array([self._row[int(i)] for i in ids], np.int64)

    def features(self, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """What the observation shows of the people ids (n,): the calibration (n, T) m of each step (the prior,
        0 m, where none is known) and the counts (n,) of step-1 errors in the window (0..window). Read-only."""
        key = np.asarray(ids, np.int64).tobytes()
        if self._shown[0] == key:
            return self._shown[1]
        rows = np.array([self._row.get(int(i), -1) for i in np.asarray(ids)], np.int64)
        known = rows >= 0
        quantile = np.full((len(rows), self.pred_len), PRIOR_ERROR_M)
        counts = np.zeros(len(rows))
        quantile[known] = self._quantile[rows[known]]
        counts[known] = np.minimum(self._count[rows[known], 0], self.window)
        self._shown = (key, (quantile, counts))
        return quantile, counts


def _pad_samples(points: np.ndarray, k: int) -> np.ndarray:
    """points (E, T, K', 2) with NaN samples added up to k."""
    if points.shape[2] == k:
        return points
    pad = np.full((*points.shape[:2], k - points.shape[2], 2), np.nan)
    return np.concatenate([points, pad], axis=2)


def episode_calibration(config: ObservationConfig, pred_len: int) -> PredictionCalibration | None:
    """A fresh calibration for an episode of an env observing with `config` (None without prediction_calibration)."""
    if not config.prediction_calibration:
        return None
    return PredictionCalibration(config.calibration_alpha, config.calibration_window, pred_len)
