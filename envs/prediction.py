"""The one prediction path of the env and its policies: load a predictor by name, call it on a history window.

Both the env (predictions in the observation, `ObservationConfig.predictions`) and the MPC policy (`mpc-gpgraph`)
load their predictor with `load_predictor_spec` and draw samples with `predict`, each with its own Generator; each
checks the predictor's timing against the env's (`envs.timing`). `true_future` is the observation's oracle source.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from envs.config import DEFAULT_PREDICTOR
from envs.factories import is_plugin, load_factory
from envs.timing import PredictionTiming
from envs.view import Pedestrians


def load_predictor_spec(spec: str | None, threads: int | None = 1, timing: PredictionTiming | None = None) -> Any:
    """A predictor from a name or checkpoint (`predictor.load_predictor`; None: `DEFAULT_PREDICTOR`) or a
    `module:factory` plug-in. threads: torch threads to set first (None: leave them). timing: the env's; a predictor
    declaring another raises ValueError."""
    if spec is not None and is_plugin(spec):
        predictor = load_factory(spec)()
    else:
        from predictor import load_predictor, set_threads  # lazy: torch only where a predictor is used

        if threads is not None:
            set_threads(threads)
        predictor = load_predictor(spec or DEFAULT_PREDICTOR)
    if timing is not None:  # the env's history and the predictor's must be the same grid
        timing.check_matches(PredictionTiming.of(predictor), "the predictor")
    return predictor


def predict(predictor: Any, history: np.ndarray, n_samples: int, rng: np.random.Generator,
            pred_len: int, track: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Samples (K, pred_len, N, 2) m and group ids (N,) for a history (obs_len, N, 2) m; with nobody in view,
    (1, pred_len, 0, 2) and (0,) without calling the predictor (and without drawing from `rng`). `track` (H, N, 2)
    m (`CrowdNavEnv.track_window`) goes to a predictor that declares `reads_track` (its group rule reads it); one
    that does not must not be given one (ValueError)."""
    if history.shape[1] == 0:
        return np.zeros((1, pred_len, 0, 2)), np.zeros(0, np.int64)
    if track is None:
        pred = predictor.predict(history, n_samples=n_samples, rng=rng)
    elif getattr(predictor, "reads_track", False):
        pred = predictor.predict(history, n_samples=n_samples, rng=rng, track=track)
    else:
        raise ValueError(f"{type(predictor).__name__} reads no track (no reads_track); give it the history only")
    return pred.samples, pred.group_id



def oracle_prediction(crowd: Any, p: Pedestrians, timing: PredictionTiming) -> tuple[np.ndarray, np.ndarray]:
    """The observation's oracle source (`ObservationConfig.prediction_source` "oracle"): the true future of the
    pedestrians p as one sample (1, pred_len, N, 2) m (`true_future`) and their true group ids (N,)."""
    return true_future(crowd, p.ped_id, p.pos, timing.step_s, timing.pred_len), p.group_id


def true_future(crowd: Any, ped_ids: np.ndarray, pos: np.ndarray, step_s: float,
                pred_len: int) -> np.ndarray:
    """The oracle's prediction (`ObservationConfig.prediction_source` "oracle"): where the pedestrians ped_ids (N,),
    now at pos (N, 2) m, will truly be at +step_s ... +pred_len step_s, as one sample (1, pred_len, N, 2) m
    (`Crowd.future`, privileged); one who leaves within the horizon is held where last seen. ValueError when the crowd
    cannot tell its future."""
    if len(ped_ids) == 0:
        return np.zeros((1, pred_len, 0, 2))
    if not hasattr(crowd, "future"):
        raise ValueError(f"prediction_source 'oracle' needs a crowd that can tell its future; "
                         f"{type(crowd).__name__} cannot")
    future = np.concatenate([np.asarray(pos, float)[None], crowd.future(ped_ids, step_s * np.arange(1, pred_len + 1))])
    for k in range(1, len(future)):  # hold the last known position where a track has ended
        gone = np.isnan(future[k, :, 0])
        future[k, gone] = future[k - 1, gone]
    return future[None, 1:]
