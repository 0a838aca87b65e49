"""The packages fit together through files: crowdsim's dataset export is read by the predictor's loader."""

from __future__ import annotations

import numpy as np

from crowdsim.cli import main as crowdsim_main
from predictor.windows import has_labels, load_windows


def test_predictor_reads_a_crowdsim_dataset_with_its_group_labels(tmp_path):
    assert crowdsim_main(["dataset", "--scenarios", "plaza", "--seeds-per-scenario", "3", "--pedestrians", "20",
                          "--duration", "20", "--merge-rate", "0.05", "--leave-rate", "0.05",
                          "--out", str(tmp_path)]) == 0
    for split in ("train", "val", "test"):
        windows = load_windows(tmp_path / split)
        assert len(windows) > 10 and has_labels(windows)
        assert all(w.obs.shape == (8, w.n_peds, 2) and w.group_id.shape == (w.n_peds,) for w in windows)
        assert any(len(np.unique(w.group_id)) < w.n_peds for w in windows)  # some pedestrians share a group
