"""Where `gpgraph train` gets its validation windows: a folder's own ``val/`` split, or a held-out time block.

A forecasting model chosen on the windows it trained on is chosen on nothing: overlapping stride-1 windows share
19 of their 20 frames, so even a random subset of windows would leak. ``holdout_windows`` therefore cuts each
recording once in time: its first ``1 - fraction`` of frames give the training windows, the last ``fraction``
the validation windows, and no window crosses the cut (each is cut from one side only), so no position is in both.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from predictor.data import Recording, check_data_step, read_split
from predictor.ethucy import OBS_LEN, PRED_LEN
from predictor.windows import Window, load_windows, recording_windows


def check_val_fraction(fraction: float) -> float:
    """``fraction`` if it is in (0, 0.5]; ValueError otherwise."""
    if not 0.0 < fraction <= 0.5:
        raise ValueError(f"val_fraction (--val-fraction) must be in (0, 0.5] (the share of each recording's frames "
                         f"held out), got {fraction}")
    return fraction


def split_recording(rec: Recording, fraction: float) -> tuple[Recording, Recording]:
    """(earlier, later) parts of ``rec``: the later holds the last ``round(fraction * F)`` of its F unique frames
    (at least one window's 20 when the recording has 40 or more), the earlier the rest; rows and per-frame labels
    are split at the same frame, the group file's groups go to both."""
    frames = np.unique(rec.rows[:, 0])
    seq_len = OBS_LEN + PRED_LEN
    n_late = int(round(fraction * len(frames)))
    if len(frames) >= 2 * seq_len:
        n_late = min(max(n_late, seq_len), len(frames) - seq_len)
    cut = frames[len(frames) - n_late] if n_late > 0 else np.inf

    def part(early: bool) -> Recording:
        rows = rec.rows[(rec.rows[:, 0] < cut) == early]
        labels = rec.frame_labels
        if labels is not None:
            labels = labels[(labels[:, 0] < cut) == early]
        return replace(rec, rows=rows, frame_labels=labels)

    return part(True), part(False)


def holdout_windows(folder: str | Path, fraction: float) -> tuple[list[Window], list[Window]]:
    """(training, validation) windows of every recording in ``folder``: each recording split in time by
    ``split_recording`` (the last ``fraction`` of its frames validate), windows cut from each part alone."""
    check_val_fraction(fraction)
    train: list[Window] = []
    val: list[Window] = []
    for rec in read_split(folder):
        early, late = split_recording(rec, fraction)
        train += recording_windows(early)
        val += recording_windows(late)
    return train, val


def _some(windows: list[Window], folder: Path) -> list[Window]:
    if not windows:
        raise ValueError(f"no windows with >= 2 pedestrians present for 20 steps in {folder}")
    return windows


def train_val_windows(data: str | Path, val_fraction: float | None) -> tuple[list[Window], list[Window], str]:
    """(training, validation) windows of ``gpgraph train --data DATA`` and where the validation ones come from:
    DATA/val (training: DATA/train), or with ``val_fraction`` the last part of each recording's frames of
    DATA/train (or of DATA itself without train/; ``holdout_windows``). Never the training windows themselves:
    DATA without val/ and without ``val_fraction`` is a ValueError naming both fixes; so is a fraction given
    beside a val/ folder (it would be ignored)."""
    data = Path(data)
    train_folder = data / "train" if (data / "train").is_dir() else data
    check_data_step(train_folder)  # also: no such folder
    if (data / "val").is_dir():
        if val_fraction is not None:
            raise ValueError(f"--val-fraction {val_fraction:g}: {data} has its own val/ split, which is used; drop "
                             "--val-fraction")
        check_data_step(data / "val")
        train, val = load_windows(train_folder), load_windows(data / "val")
        return _some(train, train_folder), _some(val, data / "val"), str(data / "val")
    if val_fraction is None:
        raise ValueError(f"{data} has no val/ folder, and a checkpoint chosen on its own training windows is not "
                         "validated; give a folder with train/ and val/ (e.g. ../shared/datasets/eth_ucy/hotel) or "
                         "add --val-fraction 0.2 (validate on the last 20% of each recording's frames)")
    train, val = holdout_windows(train_folder, val_fraction)
    if not train or not val:
        raise ValueError(f"--val-fraction {val_fraction:g}: {len(train)} training / {len(val)} validation windows "
                         f"in {train_folder}; too short to split (a window spans {OBS_LEN + PRED_LEN} frames)")
    return train, val, f"the last {val_fraction:g} of each recording's frames in {train_folder}"
