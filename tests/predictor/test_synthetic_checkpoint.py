"""The packaged default predictor `gpgraph-stgcnn-synthetic` (GP-Graph+S on STGCNN with the pairwise group
assigner, trained on crowdsim's `realistic-v1` preset by scripts/synthetic_predictor.sh) on freshly simulated
crowds it has never seen.

It must load by name with no network, forecast better than constant velocity on a crowd from its training
distribution (a preset plaza), and find the simulator's groups in the default plaza far better than trivial
groupings (all singletons; a distance threshold at the last observed step). In the default plaza it does not
beat constant velocity (an expected failure, with the numbers; RESULTS.md, section "Default synthetic
predictor").
"""

from __future__ import annotations

import numpy as np
import pytest

from crowdsim import SimConfig
from crowdsim.generate import RunSpec, generate
from crowdsim.presets import REALISTIC_V1, sample_config
from predictor import GPGraphPredictor, load_predictor, metrics
from predictor.checkpoint import PACKAGE_CHECKPOINTS
from predictor.windows import Window, load_windows

NAME = "gpgraph-stgcnn-synthetic"
SEED = 424242  # training used preset seeds 1000-1035 (no plaza seed near this one)
DURATION_S = 60.0
# Floors, with margin below what the shipped checkpoint measured with seed 424242 (version 4, trained 2026-11-25: the
# pairwise group assigner, average linkage at 1.1 x the learned threshold, from its meta, chosen on the crowdsim
# validation split). Measured 2026-11-26 on crowdsim after its groups were made to walk as real ones do (members no
# longer repel each other as strangers, d0 0.6 m, rows of 4-5 look round; RESULTS.md "sim-to-real"): best-of-20 ADE
# on the preset plaza 0.544 vs 0.690 m for constant velocity (0.79x); in the default 30-person plaza PW
# precision/recall 0.93/0.85, PW F1 0.89 vs 0.76 for the best last-step distance threshold (1 m; members walk closer
# now, so distance finds them better: before, 0.83 vs 0.55 at 2 m), G-MITRE F1 0.93 vs 0.29 for all singletons;
# best-of-20 ADE there 0.516 vs 0.563 m (0.92x; before the change 1.03x, an expected failure).
MAX_ADE_RATIO = 0.90  # best-of-20 ADE of the model / that of constant velocity, on its training distribution
MAX_ADE_RATIO_DEFAULT_PLAZA = 0.97  # ... and in the default plaza (xfail)
MIN_PW_PRECISION = 0.90
MIN_PW_RECALL = 0.65
GMITRE_F1_MARGIN = 0.5  # over all singletons
PROXIMITY_RADII_M = (0.9, 1.0, 1.1, 1.2, 1.3, 1.5, 2.0)  # members spawn 0.75 m apart
PW_F1_MARGIN_OVER_PROXIMITY = 0.08  # over the best of these radii, chosen in hindsight


def _windows(folder, config: SimConfig) -> list[Window]:
    generate(config, RunSpec(duration_s=DURATION_S, seed=SEED), folder)
    windows = load_windows(folder)
    assert len(windows) > 100 and all(w.group_id is not None for w in windows)
    return windows


@pytest.fixture(scope="module")
def plaza(tmp_path_factory: pytest.TempPathFactory) -> list[Window]:
    """Windows (8 observed + 12 future steps, per-frame group labels) of 60 s of the default 30-person plaza."""
    return _windows(tmp_path_factory.mktemp("plaza"), SimConfig(scenario="plaza", n_pedestrians=30))


@pytest.fixture(scope="module")
def preset_plaza(tmp_path_factory: pytest.TempPathFactory) -> list[Window]:
    """60 s of a plaza drawn from the training preset (realistic-v1) with a seed it never trained on."""
    return _windows(tmp_path_factory.mktemp("preset"), sample_config(REALISTIC_V1, "plaza", SEED))


def _ade_ratio(model: GPGraphPredictor, windows: list[Window]) -> tuple[float, float]:
    """Best-of-20 ADE (m) of the model and of constant velocity on the same windows (rng seed 0)."""
    cv = load_predictor("constant-velocity")
    rng = np.random.default_rng(0)
    ade = {"model": 0.0, "cv": 0.0}
    n = 0
    for w in windows:
        ade["model"] += metrics.ade_fde(model.predict(w.obs, 20, rng).samples, w.pred)[0].sum()
        ade["cv"] += metrics.ade_fde(cv.predict(w.obs, 20, rng).samples, w.pred)[0].sum()
        n += w.n_peds
    return ade["model"] / n, ade["cv"] / n


@pytest.fixture(scope="module")
def model() -> GPGraphPredictor:
    return load_predictor(NAME)


def test_packaged_by_name(model: GPGraphPredictor) -> None:
    assert (PACKAGE_CHECKPOINTS / f"{NAME}.safetensors").is_file()
    cfg = model.model.config
    assert cfg.backbone == "stgcnn" and cfg.uses_groups and cfg.bce_weight > 0  # GP-Graph+S
    assert cfg.assigner == "pairwise"


def test_beats_constant_velocity_best_of_20_on_its_training_distribution(
        model: GPGraphPredictor, preset_plaza: list[Window]) -> None:
    model_ade, cv_ade = _ade_ratio(model, preset_plaza)
    assert model_ade < MAX_ADE_RATIO * cv_ade, (model_ade, cv_ade)


def test_beats_constant_velocity_best_of_20_in_the_default_plaza(model: GPGraphPredictor, plaza: list[Window]) -> None:
    model_ade, cv_ade = _ade_ratio(model, plaza)
    assert model_ade < MAX_ADE_RATIO_DEFAULT_PLAZA * cv_ade, (model_ade, cv_ade)


def _proximity(obs: np.ndarray, radius_m: float) -> np.ndarray:
    from scipy.sparse.csgraph import connected_components

    d = np.linalg.norm(obs[-1][:, None] - obs[-1][None], axis=-1)
    return connected_components(d < radius_m, directed=False)[1]


def _f1(scores: dict[str, float], kind: str) -> float:
    p, r = scores[f"{kind}_precision"], scores[f"{kind}_recall"]
    return 2 * p * r / (p + r) if p + r > 0 else 0.0


def test_groups_match_simulator_labels(model: GPGraphPredictor, plaza: list[Window]) -> None:
    learned, singletons = metrics.GroupScores(), metrics.GroupScores()
    near = {r: metrics.GroupScores() for r in PROXIMITY_RADII_M}
    rng = np.random.default_rng(0)
    for w in plaza:
        learned.add(w.group_id, model.predict(w.obs, 1, rng).group_id)
        singletons.add(w.group_id, np.arange(w.n_peds))
        for r, scores in near.items():
            scores.add(w.group_id, _proximity(w.obs, r))
    got, alone = learned.result(), singletons.result()
    assert alone["pw_recall"] == 0.0  # all singletons find no same-group pair
    assert got["pw_precision"] > MIN_PW_PRECISION and got["pw_recall"] > MIN_PW_RECALL, got
    assert _f1(got, "gmitre") > _f1(alone, "gmitre") + GMITRE_F1_MARGIN, (got, alone)
    # a distance threshold at the last observed step finds pairs too, but the learned groups are better
    best_proximity = max(_f1(scores.result(), "pw") for scores in near.values())
    assert _f1(got, "pw") > best_proximity + PW_F1_MARGIN_OVER_PROXIMITY, (got, best_proximity)
