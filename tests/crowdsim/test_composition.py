"""Stationary group composition: under continuous inflow the share of people in groups stays at the one the
size distribution implies, for the whole run and for small and large crowds alike."""

from __future__ import annotations

import numpy as np
import pytest

from crowdsim.config import GroupConfig, SimConfig
from crowdsim.sim import CrowdSimulator


def expected_share(cfg: GroupConfig) -> float:
    """Share of people in groups of 2+ when group sizes follow cfg's distribution (size-biased)."""
    p = np.asarray(cfg.size_probabilities())
    sizes = np.arange(1, len(p) + 1)
    return float(1.0 - p[0] / (p @ sizes))


def grouped_share(state) -> float:
    labels = state.label[state.active]
    _, inverse, counts = np.unique(labels, return_inverse=True, return_counts=True)
    return float((counts[inverse] >= 2).mean())


def composition(n: int, seed: int, steps: int = 1500, **kw) -> tuple[np.ndarray, np.ndarray]:
    """Grouped share per recorded step (steps,) and the mean share of people by group size (max_size,) over a
    plaza run of `steps` x 0.4 s (1500: 10 minutes)."""
    sim = CrowdSimulator(SimConfig(scenario="plaza", n_pedestrians=n, **kw))
    sim.reset(seed)
    shares, by_size = [], []
    for _ in range(steps):
        state = sim.step()
        _, counts = np.unique(state.label[state.active], return_counts=True)
        shares.append(float(counts[counts >= 2].sum() / counts.sum()))
        k = sim.config.groups.max_size
        by_size.append(np.bincount(np.minimum(counts, k), weights=counts, minlength=k + 1)[1:] / counts.sum())
    return np.array(shares), np.mean(by_size, axis=0)


@pytest.mark.parametrize("n", [16, 24, 60])
def test_share_in_groups_stays_at_target_for_ten_minutes(n):
    """Three seeds x 10 minutes: the share over the runs, and over their first and second halves (no drift),
    stays within 0.05 of target. (A single 5-minute stretch of a 16-person crowd is lumpy: one group of five
    is 0.31 of it.)"""
    target = expected_share(GroupConfig())
    assert target == pytest.approx(0.667, abs=0.01)
    shares = np.array([composition(n, seed)[0] for seed in (0, 1, 2)])
    for part in (shares, shares[:, :750], shares[:, 750:]):
        assert abs(part.mean() - target) < 0.05, (n, shares[:, :750].mean(), shares[:, 750:].mean())


def test_people_in_the_scene_keep_the_configured_size_composition():
    """Larger groups stay longer (they walk slower); inflow corrects for it (Little's law), so the people in
    the scene are split over group sizes as the size distribution implies, not skewed to large groups."""
    cfg = GroupConfig(size_poisson_rate=1.5)
    probs = np.asarray(cfg.size_probabilities())
    target = np.arange(1, 6) * probs / (np.arange(1, 6) @ probs)
    observed = np.mean([composition(24, seed, groups=cfg)[1] for seed in (0, 1)], axis=0)
    assert np.abs(observed - target).max() < 0.03, (observed.round(3), target.round(3))


def test_labels_are_never_reused_and_the_state_carries_them():
    sim = CrowdSimulator(SimConfig(scenario="plaza", n_pedestrians=20))
    state = sim.reset(1)
    owner: dict[int, set[int]] = {}
    for _ in range(400):
        for ped, label in zip(state.ped_id[state.active], state.label[state.active], strict=True):
            owner.setdefault(int(label), set()).add(int(ped))
        assert np.all(state.label[~state.active] == -1)
        state = sim.step()
    # a label once vacated is never handed to newcomers: each label's members arrived together
    first_seen: dict[int, int] = {}
    for label, peds in owner.items():
        first_seen[label] = min(peds)
        assert max(peds) - min(peds) < 5, (label, sorted(peds))
    assert sim.book.next_label > len(owner) - 1
