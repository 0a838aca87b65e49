"""Inference API: ``load_predictor(name_or_path).predict(history, n_samples=20, rng=None) -> Prediction``.

Numpy in, numpy out (float64, metres, 0.4 s steps); torch stays inside.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from predictor.batch import relative
from predictor.checkpoint import load_model
from predictor.device import model_device
from predictor.ethucy import OBS_LEN, PRED_LEN, STEP_S  # the ETH/UCY protocol (one definition)
from predictor.gaussian import mean_cov
from predictor.group_rules import check_obs, get_rule, split_group_rule
from predictor.model import GPGraph, check_group_mode, check_group_threshold_scale
from predictor.sampling import LatentSpec, cholesky_2x2, draw_latents, sample_positions

CONSTANT_VELOCITY_NAMES = ("constant-velocity", "cv")


@dataclass(frozen=True)
class Prediction:
    """Predicted futures for N pedestrians.

    Attributes:
        samples: (K, 12, N, 2) absolute positions at +0.4 ... +4.8 s, m.
        mean: (12, N, 2) absolute means, m (last position plus the cumulative step means).
        cov: (12, N, 2, 2) covariances of the absolute positions, m^2 (per-step covariances summed,
            treating steps as independent).
        group_id: (N,) the model's group assignment, 0..G-1.
    """

    samples: np.ndarray
    mean: np.ndarray
    cov: np.ndarray
    group_id: np.ndarray


def check_history(history: np.ndarray) -> np.ndarray:
    """Validate an (8, N, 2) finite history with N >= 1; returns it as float64."""
    h = np.asarray(history, dtype=np.float64)
    if h.ndim != 3 or h.shape[0] != OBS_LEN or h.shape[2] != 2:
        raise ValueError(f"history must have shape (8, N, 2) in metres, got {h.shape}")
    if h.shape[1] < 1:
        raise ValueError("history has no pedestrians (N = 0)")
    bad = ~np.isfinite(h)
    if bad.any():
        t, n, _ = np.argwhere(bad)[0]
        raise ValueError(f"history contains NaN or inf (first at step {t}, pedestrian {n})")
    return h


def check_track(track: np.ndarray | None, history: np.ndarray, reads_track: bool) -> np.ndarray | None:
    """Validate a longer track (H >= 8, N, 2) m for the group rule: the same N pedestrians as ``history`` (8, N, 2),
    rows 0.4 s apart, its last row equal to the history's; NaN only as a pedestrian's rows before it was first seen
    (``predictor.group_rules``). None passes through; a track for a predictor that reads none is an error."""
    if track is None:
        return None
    if not reads_track:
        raise ValueError("this predictor reads no track (its grouping reads the 8 history steps); give it none, or "
                         "group by a rule that reads one (e.g. NAME+coherent-motion-track)")
    tr = np.asarray(track, dtype=np.float64)
    if tr.ndim != 3 or tr.shape[0] < history.shape[0] or tr.shape[1:] != history.shape[1:]:
        raise ValueError(f"track must have shape (H >= {history.shape[0]}, {history.shape[1]}, 2) in metres like the "
                         f"history, got {tr.shape}")
    if not np.array_equal(tr[-1], history[-1]):
        raise ValueError("track's last row must equal the history's (the same pedestrians, now)")
    check_obs(tr)  # NaN only before a pedestrian was first seen, no inf
    return tr


def _check_inputs(history: np.ndarray, n_samples: int,
                  rng: np.random.Generator | int | None) -> tuple[np.ndarray, np.random.Generator]:
    """The checked (8, N, 2) history and the Generator to draw from: `rng` itself, a new one seeded with an
    int `rng`, or a fresh unseeded one when None; anything else raises ValueError."""
    h = check_history(history)
    if not isinstance(n_samples, int | np.integer) or n_samples < 1:
        raise ValueError(f"n_samples must be a positive integer, got {n_samples!r}")
    if rng is None or isinstance(rng, int | np.integer):
        if rng is not None and rng < 0:
            raise ValueError(f"an int rng is a seed and must be >= 0, got {rng}")
        return h, np.random.default_rng(rng)
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy Generator, an int seed or None, got {type(rng).__name__}")
    return h, rng


class GPGraphPredictor:
    """Wraps a trained ``GPGraph``; latents follow ``spec`` (default: the model's sample level)."""

    step_s, obs_len, pred_len = STEP_S, OBS_LEN, PRED_LEN  # the timing it was trained on (callers check it)

    def __init__(self, model: GPGraph, spec: LatentSpec | None = None) -> None:
        self.model = model.eval()
        self.spec = spec or LatentSpec("normal", model.config.sample_level, per_step=True)

    @property
    def track_steps(self) -> int:
        """Positions per pedestrian its grouping reads: its group rule's ``track_steps``, else the 8 of ``history``."""
        uses_rule = self.model.group_rule is not None and self.model.config.uses_groups
        return get_rule(self.model.group_rule).track_steps if uses_rule else OBS_LEN

    @property
    def reads_track(self) -> bool:
        """Whether it reads ``predict``'s ``track``: its group rule reads more than the 8 steps of ``history``."""
        return self.track_steps > OBS_LEN

    @torch.no_grad()
    def predict(
        self, history: np.ndarray, n_samples: int = 20, rng: np.random.Generator | int | None = None,
        track: np.ndarray | None = None,
    ) -> Prediction:
        """Sample ``n_samples`` futures from ``history`` (8, N, 2), m. Same rng state, same samples.

        ``track`` (H >= 8, N, 2) m, only for a predictor that ``reads_track``: the same pedestrians' longer past
        (``check_track``), which its group rule reads (its newest ``track_steps`` rows) instead of the 8 steps; the
        forecast itself reads ``history`` only. Without one such a rule reads ``history``."""
        h, rng = _check_inputs(history, n_samples, rng)
        tr = check_track(track, h, self.reads_track)
        rule_obs = None if tr is None else tr[None]
        device = model_device(self.model)  # the model's forward runs there; sampling stays on the CPU
        obs_abs = torch.as_tensor(h, dtype=torch.float32, device=device)[None]
        obs_rel = torch.as_tensor(relative(h), dtype=torch.float32, device=device)[None]
        out = self.model(obs_abs, obs_rel, torch.ones(1, h.shape[1], dtype=torch.bool, device=device), rule_obs)
        mu, cov = (a[0].double().numpy() for a in mean_cov(out.raw.cpu()))
        groups = out.groups[0].cpu().numpy().astype(np.int64)
        z = draw_latents(self.spec, n_samples, PRED_LEN, groups, rng)
        with np.errstate(invalid="ignore", over="ignore"):
            samples = sample_positions(mu, cholesky_2x2(cov), z, h[-1])
        if not (np.all(np.isfinite(samples)) and np.all(np.isfinite(mu)) and np.all(np.isfinite(cov))):
            step = float(np.nanmax(np.linalg.norm(np.diff(h, axis=0), axis=-1))) if len(h) > 1 else 0.0
            raise ValueError("the model's prediction is not finite for this history (largest observed step "
                             f"{step:.3g} m per 0.4 s); histories must be in metres at 0.4 s steps, as trained")
        return Prediction(samples, h[-1] + np.cumsum(mu, axis=0), np.cumsum(cov, axis=0), groups)


@dataclass(frozen=True)
class ConstantVelocityConfig:
    """Constant-velocity baseline.

    Attributes:
        velocity_steps: observed steps averaged for the velocity estimate (1..7).
        step_noise_m: per-step standard deviation of the velocity perturbation, m per 0.4 s step.
    """

    velocity_steps: int = 1
    step_noise_m: float = 0.05

    def __post_init__(self) -> None:
        if not 1 <= self.velocity_steps < OBS_LEN:
            raise ValueError(f"velocity_steps must be in 1..{OBS_LEN - 1}, got {self.velocity_steps}")
        if self.step_noise_m < 0:
            raise ValueError(f"step_noise_m must be >= 0, got {self.step_noise_m}")


class ConstantVelocityPredictor:
    """Extrapolates the last observed velocity; samples perturb the velocity with isotropic noise.

    Every pedestrian is its own group, unless ``group_rule`` (a ``predictor.group_rules`` name) groups them.
    """

    step_s, obs_len, pred_len = STEP_S, OBS_LEN, PRED_LEN

    def __init__(self, config: ConstantVelocityConfig | None = None, group_rule: str | None = None) -> None:
        self.config = config or ConstantVelocityConfig()
        self.group_rule = get_rule(group_rule) if group_rule is not None else None

    @property
    def track_steps(self) -> int:
        """Positions per pedestrian its grouping reads (as ``GPGraphPredictor.track_steps``)."""
        return self.group_rule.track_steps if self.group_rule is not None else OBS_LEN

    @property
    def reads_track(self) -> bool:
        """Whether it reads ``predict``'s ``track`` (as ``GPGraphPredictor.reads_track``)."""
        return self.track_steps > OBS_LEN

    def predict(
        self, history: np.ndarray, n_samples: int = 20, rng: np.random.Generator | int | None = None,
        track: np.ndarray | None = None,
    ) -> Prediction:
        """As ``GPGraphPredictor.predict``: ``track`` is what the group rule reads (when there is one)."""
        h, rng = _check_inputs(history, n_samples, rng)
        tr = check_track(track, h, self.reads_track)
        k = self.config.velocity_steps
        vel = (h[-1] - h[-1 - k]) / k  # (N, 2), m/step
        steps = np.arange(1, PRED_LEN + 1, dtype=np.float64)[:, None, None]
        mean = h[-1] + steps * vel
        sigma = self.config.step_noise_m
        noise = rng.standard_normal((n_samples, 1, h.shape[1], 2)) * sigma
        samples = mean[None] + steps[None] * noise
        var = (steps[:, :, 0] * sigma) ** 2  # (12, 1)
        cov = np.zeros((PRED_LEN, h.shape[1], 2, 2))
        cov[..., 0, 0] = cov[..., 1, 1] = var
        groups = self.group_rule(h if tr is None else tr) if self.group_rule is not None else np.arange(h.shape[1])
        return Prediction(samples, mean, cov, groups)


def load_predictor(
    name_or_path: str | Path, backbone: str | None = None, grouping: str | None = None,
    group_threshold_scale: float | None = None, group_mode: str | None = None, group_rule: str | None = None,
) -> GPGraphPredictor | ConstantVelocityPredictor:
    """A predictor by packaged name ('gpgraph-stgcnn-hotel', 'constant-velocity') or checkpoint path.

    ``group_rule`` (a ``predictor.group_rules.GROUP_RULES`` name, e.g. "coherent-motion") replaces the model's
    learned hard group assignment at inference (``GPGraph.group_rule``; for constant velocity: groups its
    pedestrians). A name "NAME+RULE" (e.g. "gpgraph-stgcnn-synthetic+coherent-motion") says the same in one string,
    so that everything that takes a predictor name (the env, the benchmark's suites, ``crowdnav --predictor``)
    can choose it; giving both is an error.

    ``backbone``/``grouping`` apply to checkpoint files (a published reference file defaults to
    backbone 'sgcn' with 'official' grouping). ``group_threshold_scale`` (finite, > 0) multiplies the learned
    group threshold at inference (below 1: fewer, smaller groups; see ``GPGraph``); None keeps the
    checkpoint's calibrated value, or 1.0 when it has none. ``group_mode`` ('exact', 'official' or 'average':
    average-linkage clustering of the learned distances, see ``GPGraph``) overrides the hard grouping at
    inference; None keeps the checkpoint's, or the grouping it was trained with. Both are checked, then
    ignored, for constant velocity.
    """
    name, spec_rule = split_group_rule(name_or_path)
    if spec_rule is not None:
        if group_rule is not None:
            raise ValueError(f"predictor {str(name_or_path)!r} names a group rule and group_rule={group_rule!r} "
                             "names another: give one")
        group_rule = spec_rule
    if name in CONSTANT_VELOCITY_NAMES:  # load_model checks the options for every other name
        if group_threshold_scale is not None:
            check_group_threshold_scale(group_threshold_scale)
        check_group_mode(group_mode)
        return ConstantVelocityPredictor(group_rule=group_rule)
    model, _ = load_model(name, backbone=backbone, grouping=grouping,
                          group_threshold_scale=group_threshold_scale, group_mode=group_mode, group_rule=group_rule)
    return GPGraphPredictor(model)


def set_threads(n: int) -> None:
    """Set torch's intra-op threads for this process (callers outside `predictor` never import torch).
    On a small CPU, one thread per process avoids oversubscription when several processes run."""
    if not isinstance(n, int) or n < 1:
        raise ValueError(f"threads must be a positive integer, got {n!r}")
    torch.set_num_threads(n)
