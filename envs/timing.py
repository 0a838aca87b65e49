"""The prediction timing every part of the env agrees on: the 0.4 s step, 8 observed and 12 predicted steps.

It is read from the loaded predictor (`PredictionTiming.of(predictor)`: its `step_s`, `obs_len` and `pred_len`
attributes) and defaults to the ETH/UCY protocol that the packaged predictors follow (`DEFAULT_TIMING`, built from
its one definition in `predictor.ethucy`). The env's history, observation and the policies' view all take it
from here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from predictor.ethucy import OBS_LEN, PRED_LEN, STEP_S  # torch-free


@dataclass(frozen=True)
class PredictionTiming:
    """step_s: time between history rows and between predicted steps, s; obs_len: observed rows (the last is
    now); pred_len: predicted steps (+step_s ... +pred_len * step_s)."""

    step_s: float
    obs_len: int
    pred_len: int

    def __post_init__(self) -> None:
        if not self.step_s > 0 or self.obs_len < 2 or self.pred_len < 1:
            raise ValueError(f"invalid prediction timing {self}: need step_s > 0, obs_len >= 2, pred_len >= 1")

    @classmethod
    def of(cls, predictor: Any) -> PredictionTiming:
        """The timing a predictor declares (attributes `step_s`, `obs_len`, `pred_len`; defaults otherwise)."""
        d = DEFAULT_TIMING
        return cls(float(getattr(predictor, "step_s", d.step_s)), int(getattr(predictor, "obs_len", d.obs_len)),
                   int(getattr(predictor, "pred_len", d.pred_len)))

    def check_matches(self, other: PredictionTiming, who: str) -> None:
        """Raise ValueError when `other` (a loaded predictor's timing) differs from this (the env's)."""
        if other != self:
            raise ValueError(f"{who} predicts with {other}, but the env runs {self}")


DEFAULT_TIMING = PredictionTiming(STEP_S, OBS_LEN, PRED_LEN)
