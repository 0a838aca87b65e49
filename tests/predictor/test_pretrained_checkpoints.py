"""The packaged crowdsim-pretrained ETH/UCY predictors `gpgraph-stgcnn-<scene>-pretrained`
(scripts/synthetic_pretraining.sh package; RESULTS.md "What crowdsim pretraining buys on real data").

Each one never saw its scene in training, and over the five ETH/UCY test scenes they forecast better than the
packaged real-only `gpgraph-stgcnn-<scene>` (120 epochs from random weights). Measured with seed 0 and one trial,
five-scene mean best-of-20 FDE: paper 0.446 vs 0.478 m, iid 0.715 vs 0.764 m (per scene, paper: eth 0.80 vs
0.91, hotel 0.36 vs 0.35, univ 0.41 vs 0.42, zara1 0.34 vs 0.37, zara2 0.31 vs 0.34).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from predictor.checkpoint import load_model
from predictor.ethucy import DEFAULT_DATA_DIR
from predictor.evaluate import EvalConfig, evaluate
from predictor.windows import load_windows

SCENES = ("eth", "hotel", "univ", "zara1", "zara2")
DATA = DEFAULT_DATA_DIR
TEST_FILE = {"eth": "biwi_eth", "hotel": "biwi_hotel", "univ": "students", "zara1": "crowds_zara01",
             "zara2": "crowds_zara02"}


@pytest.mark.parametrize("scene", SCENES)
def test_pretrained_checkpoint_records_how_it_was_made_and_never_saw_its_scene(scene):
    _, meta = load_model(f"gpgraph-stgcnn-{scene}-pretrained")
    assert meta["scene"] == scene
    assert meta["train"]["init"] == "gpgraph-stgcnn-synthetic" and meta["train"]["lr"] == 0.001
    assert "leave-one-scene-out" in meta["note"]
    assert meta["data"]["train"] and not any(name.startswith(TEST_FILE[scene]) for name in meta["data"]["train"])


@pytest.mark.slow
@pytest.mark.parametrize("protocol, margin_m", [("paper", 0.02), ("iid", 0.02)])
def test_pretrained_beats_real_only_on_the_five_test_scenes(protocol, margin_m):
    if not DATA.is_dir():
        pytest.skip(f"{DATA} is not here")
    torch.set_num_threads(1)
    fde = {"pretrained": [], "real-only": []}
    for scene in SCENES:
        windows = load_windows(DATA / scene / "test")
        pair = (("pretrained", f"gpgraph-stgcnn-{scene}-pretrained"), ("real-only", f"gpgraph-stgcnn-{scene}"))
        for kind, name in pair:
            model, _ = load_model(name)
            result = evaluate(model, windows, EvalConfig(protocol=protocol, seed=0, trials=1), ade_fde_only=True)
            fde[kind].append(result["fde"])
    assert np.mean(fde["pretrained"]) < np.mean(fde["real-only"]) - margin_m, fde
