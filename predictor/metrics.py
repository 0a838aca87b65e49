"""Trajectory and group metrics.

Trajectory metrics take ``samples`` (K, T, N, 2) and ground truth ``gt`` (T, N, 2), absolute positions in
metres, and return one value per pedestrian (N,); average over all pedestrians of a test set to report.
Group metrics compare two labelings (N,) of the same pedestrians and return summable counts, so a test
set is scored by summing counts over windows before dividing.
"""

from __future__ import annotations

import numpy as np

COL_THRESHOLD_M = 0.2
COL_INTERP = 4
COL_POINTS = 3 * COL_INTERP + 2


def ade_fde(samples: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Best-of-K ADE and FDE per pedestrian (N,), m: minimum over samples, separately for each pedestrian."""
    err = np.linalg.norm(samples - gt[None], axis=-1)  # (K, T, N)
    return err.mean(axis=1).min(axis=0), err[:, -1].min(axis=0)


def best_fde_index(samples: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Index (N,) of each pedestrian's sample with the smallest final displacement error."""
    return np.linalg.norm(samples[:, -1] - gt[-1][None], axis=-1).argmin(axis=0)


def tcc(samples: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Temporal correlation coefficient per pedestrian (N,).

    Pearson correlation over time between the best-FDE sample and the ground truth, computed for x and
    for y and averaged; a constant series (undefined correlation) counts as 0.
    """
    n = gt.shape[1]
    best = samples[best_fde_index(samples, gt), :, np.arange(n)]  # (N, T, 2)
    truth = np.transpose(gt, (1, 0, 2))
    a = best - best.mean(axis=1, keepdims=True)
    b = truth - truth.mean(axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = (a * b).sum(axis=1) / np.sqrt((a * a).sum(axis=1) * (b * b).sum(axis=1))
    r = np.nan_to_num(np.clip(r, -1.0, 1.0), nan=0.0)
    return r.mean(axis=-1)


def interpolate(samples: np.ndarray, factor: int = COL_INTERP) -> np.ndarray:
    """Linearly densify (K, T, N, 2) predictions to (K, 1 + factor (T - 1), N, 2), starting at the first step."""
    steps = np.diff(samples, axis=1) / factor  # (K, T-1, N, 2)
    dense = np.repeat(steps, factor, axis=1)
    return np.concatenate([samples[:, :1], samples[:, :1] + np.cumsum(dense, axis=1)], axis=1)


def col(samples: np.ndarray, threshold: float = COL_THRESHOLD_M, n_points: int = COL_POINTS) -> np.ndarray:
    """Collision rate per pedestrian (N,), in percent of samples.

    As in the GP-Graph evaluation: predictions are interpolated 4x, only the first ``n_points`` (14)
    interpolated points are checked, and a pedestrian collides in sample k if any other pedestrian of the
    same sample k comes closer than ``threshold`` metres at the same instant.
    """
    dense = interpolate(samples)[:, :n_points]  # (K, P, N, 2)
    n = samples.shape[2]
    d = np.linalg.norm(dense[:, :, :, None] - dense[:, :, None, :], axis=-1)  # (K, P, N, N)
    d = d + np.eye(n)[None, None] * 1e9
    hit = (d.min(axis=1) < threshold).any(axis=-1)  # (K, N)
    return hit.mean(axis=0) * 100.0


def same_group_pairs(labels: np.ndarray) -> set[tuple[int, int]]:
    """Unordered pairs (i, j), i < j, of pedestrians that share a label."""
    labels = np.asarray(labels)
    i, j = np.nonzero(np.triu(labels[:, None] == labels[None, :], k=1))
    return set(zip(i.tolist(), j.tolist(), strict=True))


def pw_counts(truth: np.ndarray, pred: np.ndarray) -> tuple[int, int, int]:
    """Pairwise counts (true positives, predicted same-group pairs, true same-group pairs)."""
    t, p = same_group_pairs(truth), same_group_pairs(pred)
    return len(t & p), len(p), len(t)


def _clusters(labels: np.ndarray) -> list[set[int]]:
    return [set(np.flatnonzero(labels == g).tolist()) for g in np.unique(labels)]


def _with_fake_partners(key: np.ndarray, response: np.ndarray) -> tuple[list[set[int]], list[set[int]]]:
    """Give each pedestrian that is a singleton in either partition a fake partner (G-MITRE).

    The fake joins its pedestrian's cluster in every partition where that pedestrian is alone, and
    is a singleton of its own elsewhere. Fake element ids start at N.
    """
    key, response = np.asarray(key), np.asarray(response)
    kc, rc = _clusters(key), _clusters(response)
    n = len(key)
    fake = n
    for idx in range(n):
        k_single = [c for c in kc if c == {idx}]
        r_single = [c for c in rc if c == {idx}]
        if not k_single and not r_single:
            continue
        for single, clusters in ((k_single, kc), (r_single, rc)):
            if single:
                single[0].add(fake)
            else:
                clusters.append({fake})
        fake += 1
    return kc, rc


def _mitre_recall_counts(key: list[set[int]], response: list[set[int]]) -> tuple[int, int]:
    """MITRE recall numerator and denominator: sum(|c| - #response clusters c touches), sum(|c| - 1)."""
    owner = {e: i for i, c in enumerate(response) for e in c}
    num = sum(len(c) - len({owner[e] for e in c}) for c in key)
    den = sum(len(c) - 1 for c in key)
    return num, den


def mitre_counts(truth: np.ndarray, pred: np.ndarray) -> tuple[int, int, int, int]:
    """G-MITRE counts (recall numerator, recall denominator, precision numerator, precision denominator)."""
    kc, rc = _with_fake_partners(truth, pred)
    r_num, r_den = _mitre_recall_counts(kc, rc)
    p_num, p_den = _mitre_recall_counts(rc, kc)
    return r_num, r_den, p_num, p_den


def ratio(num: float, den: float) -> float:
    """num / den, or NaN when den is 0."""
    return float(num) / float(den) if den else float("nan")


def f1(precision: float | None, recall: float | None) -> float:
    """Harmonic mean of precision and recall (e.g. PW or G-MITRE F1); NaN when either is missing (None or NaN),
    0 when both are 0."""
    if precision is None or recall is None or precision != precision or recall != recall:
        return float("nan")
    return 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0


class GroupScores:
    """Accumulates PW and G-MITRE counts over windows."""

    def __init__(self) -> None:
        self.counts = np.zeros(7, dtype=np.int64)

    def add(self, truth: np.ndarray, pred: np.ndarray) -> None:
        """Add one window's labelings (N,) each."""
        self.counts += np.array(pw_counts(truth, pred) + mitre_counts(truth, pred), dtype=np.int64)

    def result(self) -> dict[str, float]:
        """``pw_precision``, ``pw_recall``, ``gmitre_precision``, ``gmitre_recall`` over everything added."""
        tp, n_pred, n_true, r_num, r_den, p_num, p_den = self.counts.tolist()
        return {
            "pw_precision": ratio(tp, n_pred),
            "pw_recall": ratio(tp, n_true),
            "gmitre_precision": ratio(p_num, p_den),
            "gmitre_recall": ratio(r_num, r_den),
        }
