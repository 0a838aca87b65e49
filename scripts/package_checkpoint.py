"""Copy a training run's ``best.pt`` into a packaged ``.safetensors`` checkpoint (config and meta inside).

    python scripts/package_checkpoint.py out/run/best.pt predictor/checkpoints/NAME.safetensors \
        --scene synthetic --data out/synthetic_predictor/data

The meta keeps what ``best.pt`` recorded (epoch, validation loss, training recipe) plus ``scene`` and, with
``--data``, the names of the recordings in each split, so a shipped file says what it was trained on. With
``--group-threshold-scale X`` (chosen on the validation split, e.g. by ``scripts/sweep_group_threshold.py``) the
meta also records ``group_threshold_scale``, which ``load_model``/``load_predictor`` then apply by default;
likewise ``--group-mode NAME`` records ``group_mode`` (e.g. 'average' linkage at inference).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from predictor.checkpoint import export_packaged, load_model
from predictor.cli import group_threshold_scale_arg
from predictor.grouping import THRESHOLD_MODES


def split_files(data: Path) -> dict[str, list[str]]:
    """Trajectory file names per split folder of a crowdsim dataset."""
    out = {}
    for split in ("train", "val", "test"):
        folder = data / split
        if folder.is_dir():
            out[split] = sorted(p.name for p in folder.glob("*.txt") if not p.name.endswith(".groups.txt"))
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("checkpoint", type=Path, help="a training run's best.pt")
    p.add_argument("out", type=Path, help="destination .safetensors")
    p.add_argument("--scene", required=True, help="recorded in the meta as 'scene'")
    p.add_argument("--data", type=Path, default=None, help="dataset folder; its file names go into the meta")
    p.add_argument("--group-threshold-scale", type=group_threshold_scale_arg, default=None, metavar="X",
                   help="calibrated group threshold scale to record in the meta (default: best.pt's, else none)")
    p.add_argument("--group-mode", choices=THRESHOLD_MODES, default=None, metavar="NAME",
                   help="inference grouping to record in the meta (default: best.pt's, else none: as trained)")
    p.add_argument("--note", default=None, help="free text recorded in the meta as 'note' (how it was chosen)")
    args = p.parse_args(argv)
    if args.out.suffix != ".safetensors":
        p.error("out must end in .safetensors")
    model, meta = load_model(args.checkpoint, group_threshold_scale=args.group_threshold_scale,
                             group_mode=args.group_mode)
    meta = {**meta, "scene": args.scene}
    if args.note:
        meta["note"] = args.note
    if args.data is not None:
        meta["data"] = split_files(args.data)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    export_packaged(model, args.out, meta=meta)
    print(f"wrote {args.out} (epoch {meta.get('epoch')}, val loss {meta.get('val_loss')}, group threshold scale "
          f"{model.group_threshold_scale}, grouping {model.effective_group_mode})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
