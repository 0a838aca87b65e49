"""Test-set evaluation under a labelled sampling protocol ('iid' or 'paper').

ADE/FDE (m) are best-of-K per pedestrian; COL (percent of samples) and TCC follow the GP-Graph test
script. Each metric is averaged over ``trials`` repetitions of the sampling and over every pedestrian of
every window. PW and G-MITRE are added when the windows carry ground-truth group labels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from tqdm import tqdm

from predictor import metrics
from predictor.batch import collate
from predictor.device import model_device
from predictor.gaussian import mean_cov
from predictor.model import GPGraph
from predictor.sampling import (
    LatentSpec,
    cholesky_2x2,
    draw_latents,
    kmeans_pool,
    protocol_spec,
    sample_positions,
)
from predictor.windows import Window, has_labels


@dataclass(frozen=True)
class EvalConfig:
    """Evaluation settings.

    Attributes:
        protocol: 'iid' or 'paper' (see ``predictor.sampling.protocol_spec``).
        seed: seeds the numpy Generator of the latent draws.
        n_samples: K samples per pedestrian (best-of-K).
        trials: repetitions of the whole sampling, averaged.
        batch_size: windows per forward pass.
        pool_size: KMeans centroid sets precomputed for the 'paper' protocol.
    """

    protocol: str = "iid"
    seed: int = 0
    n_samples: int = 20
    trials: int = 20
    batch_size: int = 64
    pool_size: int = 1000

    def __post_init__(self) -> None:
        protocol_spec(self.protocol)
        if self.n_samples < 1 or self.trials < 1 or self.batch_size < 1 or self.pool_size < 1:
            raise ValueError("n_samples, trials, batch_size and pool_size must be >= 1")


@torch.no_grad()
def step_distributions(model: GPGraph, windows: list[Window]) -> list[tuple[np.ndarray, ...]]:
    """Per window: step means (12, n, 2) and Cholesky factors (12, n, 2, 2), m/step; predicted groups (n,).

    The forward pass runs on the model's device; its outputs come back to the CPU (float64) before anything
    is sampled, so the draws do not depend on the device.
    """
    batch = collate(windows).to(model_device(model))
    out = model(batch.obs_abs, batch.obs_rel, batch.node_mask)
    mu, cov = mean_cov(out.raw.cpu().double())
    groups = out.groups.cpu()
    result = []
    for i, n in enumerate(batch.counts):
        result.append((mu[i, :, :n].numpy(), cholesky_2x2(cov[i, :, :n].numpy()), groups[i, :n].numpy()))
    return result


def _score_window(
    mu: np.ndarray, chol: np.ndarray, groups: np.ndarray, w: Window, spec: LatentSpec,
    cfg: EvalConfig, rng: np.random.Generator, pool: np.ndarray | None, ade_fde_only: bool = False,
) -> np.ndarray:
    """Sums over trials of (ade, fde, col, tcc), each (n,); only (ade, fde) with ``ade_fde_only``."""
    acc = np.zeros((2 if ade_fde_only else 4, w.n_peds))
    for _ in range(cfg.trials):
        z = draw_latents(spec, cfg.n_samples, mu.shape[0], groups, rng, pool)
        samples = sample_positions(mu, chol, z, w.obs[-1])
        ade, fde = metrics.ade_fde(samples, w.pred)
        if ade_fde_only:
            acc += np.stack([ade, fde])
        else:
            acc += np.stack([ade, fde, metrics.col(samples), metrics.tcc(samples, w.pred)])
    return acc


def evaluate(
    model: GPGraph, windows: list[Window], cfg: EvalConfig | None = None, progress: bool = False,
    ade_fde_only: bool = False,
) -> dict:
    """Metrics dict with keys ade, fde (m), col (%), tcc (+ pw/gmitre when labelled) and the protocol details.

    The model runs on its own device (see ``step_distributions``); the latents come from one numpy Generator
    seeded with ``cfg.seed``. ``progress`` shows a progress bar over the windows (on stderr);
    ``ade_fde_only`` skips COL, TCC and the group metrics (same latent draws, so the same ADE/FDE).
    """
    cfg = cfg or EvalConfig()
    if not windows:
        raise ValueError("no windows to evaluate")
    model.eval()
    rng = np.random.default_rng(cfg.seed)
    spec = protocol_spec(cfg.protocol)
    pool = kmeans_pool(cfg.n_samples, cfg.pool_size, rng) if spec.kind == "kmeans" else None
    keys = ("ade", "fde") if ade_fde_only else ("ade", "fde", "col", "tcc")
    totals, n_peds = np.zeros(len(keys)), 0
    groups_scores = metrics.GroupScores() if has_labels(windows) and not ade_fde_only else None
    with tqdm(total=len(windows), desc=f"evaluate ({cfg.protocol})", unit="window", disable=not progress) as bar:
        for start in range(0, len(windows), cfg.batch_size):
            chunk = windows[start : start + cfg.batch_size]
            for w, (mu, chol, groups) in zip(chunk, step_distributions(model, chunk), strict=True):
                totals += _score_window(mu, chol, groups, w, spec, cfg, rng, pool, ade_fde_only).sum(axis=1)
                n_peds += w.n_peds
                if groups_scores is not None:
                    groups_scores.add(w.group_id, groups)
            bar.update(len(chunk))
    result = dict(zip(keys, (totals / (n_peds * cfg.trials)).tolist(), strict=True))
    if groups_scores is not None:
        result.update(groups_scores.result())
    result.update(
        protocol=cfg.protocol, seed=cfg.seed, n_samples=cfg.n_samples, trials=cfg.trials,
        windows=len(windows), pedestrians=n_peds,
    )
    return result


def evaluate_constant_velocity(windows: list[Window], seed: int, trials: int, n_samples: int) -> dict:
    """The metrics dict of `evaluate` for the constant-velocity predictor (`predictor.api`, its own sampling: last
    velocity plus per-pedestrian noise, neither 'iid' nor 'paper'): best-of-`n_samples` ADE/FDE (m), COL, TCC over
    `trials`, the all-singletons PW/G-MITRE when the windows carry labels, and ``ade_k1``/``fde_k1`` of the
    noise-free extrapolation."""
    from predictor.api import ConstantVelocityConfig, ConstantVelocityPredictor

    rng = np.random.default_rng(seed)
    cv = ConstantVelocityPredictor()
    exact = ConstantVelocityPredictor(ConstantVelocityConfig(step_noise_m=0.0))
    totals, k1, n_peds = np.zeros(4), np.zeros(2), 0
    groups = metrics.GroupScores() if has_labels(windows) else None
    for w in windows:
        for _ in range(trials):
            samples = cv.predict(w.obs, n_samples=n_samples, rng=rng).samples
            ade, fde = metrics.ade_fde(samples, w.pred)
            totals += [ade.sum(), fde.sum(), metrics.col(samples).sum(), metrics.tcc(samples, w.pred).sum()]
        ade1, fde1 = metrics.ade_fde(exact.predict(w.obs, n_samples=1).samples, w.pred)
        k1 += [ade1.sum(), fde1.sum()]
        n_peds += w.n_peds
        if groups is not None:
            groups.add(w.group_id, np.arange(w.n_peds))
    ade, fde, col, tcc = (totals / (n_peds * trials)).tolist()
    result = {"ade": ade, "fde": fde, "col": col, "tcc": tcc}
    if groups is not None:
        result.update(groups.result())
    result.update(ade_k1=k1[0] / n_peds, fde_k1=k1[1] / n_peds, protocol="constant-velocity", seed=seed,
                  n_samples=n_samples, trials=trials, windows=len(windows), pedestrians=n_peds)
    return result
