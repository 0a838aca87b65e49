"""Crowd-risk helpers of the scene builder (numpy only): how much to inflate the pedestrians' clearance.

* **Clearance inflation** (:func:`clearance_inflation`): at a checked time t (s) the clearance of a pedestrian
  grows by ``clearance_growth_mps * t + spread_inflation * spread(t)``, capped at
  ``max_clearance_inflation_m``; spread(t) is the root-mean-square distance (m) of the predictor's samples
  from their mean at t (0 now). Both are chance-constraint-like margins: the later and the less certain a
  predicted position, the wider the berth.

A speed cap near people and a ranking of the pedestrians by predicted risk were here until 2026-11-28: tried, not
adopted, removed (docs/decisions/planner-settings.md, "Removed layers"). The MPC constrains the nearest M.
"""

from __future__ import annotations

import numpy as np

from planner.config import MPCConfig


def sample_spread(positions: np.ndarray) -> np.ndarray:
    """(S, T, N, 2) samples -> (T, N) root-mean-square distance (m) of the samples from their mean."""
    dev = positions - positions.mean(axis=0, keepdims=True)
    return np.sqrt((dev * dev).sum(-1).mean(axis=0))


def resample_scalar(values: np.ndarray, step_s: float, dt_s: float, n_times: int, now: float = 0.0) -> np.ndarray:
    """(T, N) values at +step_s, .., +T step_s (``now`` at t=0) -> (n_times, N) at +dt_s, .., held after T."""
    t_known = step_s * np.arange(values.shape[0] + 1)
    known = np.concatenate([np.full((1, values.shape[1]), now), values], axis=0)
    t_query = dt_s * np.arange(1, n_times + 1)
    return np.stack([np.interp(t_query, t_known, known[:, n]) for n in range(values.shape[1])], axis=1) \
        if values.shape[1] else np.zeros((n_times, 0))


def clearance_inflation(spread: np.ndarray, cfg: MPCConfig, sub_dt_s: float) -> np.ndarray:
    """Clearance added (m) at the checked times (nt, N) from spread (nt, N) m (see the module doc)."""
    t = sub_dt_s * np.arange(1, spread.shape[0] + 1)[:, None]
    extra = cfg.clearance_growth_mps * t + cfg.spread_inflation * spread
    return np.minimum(extra, cfg.max_clearance_inflation_m)
