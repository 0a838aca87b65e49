"""``gpgraph`` command line: train, evaluate, predict.

Examples (the first: a check that training runs, under a minute; the second: the full recipe, hours)::

    gpgraph train --data ../shared/datasets/eth_ucy/hotel --out runs/hotel-quick --max-windows 512 --epochs 5
    gpgraph train --data ../shared/datasets/eth_ucy/hotel --backbone stgcnn --out runs/hotel --threads 2 \
        --eval-every 10
    gpgraph evaluate --checkpoint runs/hotel/best.pt --data ../shared/datasets/eth_ucy/hotel \
        --protocol iid --seed 0 --json hotel.json
    gpgraph evaluate --checkpoint ../shared/reference/gpgraph_sgcn/hotel/val_best.pth --backbone sgcn \
        --grouping official --data ../shared/datasets/eth_ucy/hotel --protocol paper
    gpgraph evaluate --checkpoint gpgraph-stgcnn-synthetic --data out/synthetic_predictor/data --split val \
        --group-threshold-scale 0.8
    gpgraph evaluate --checkpoint gpgraph-stgcnn-synthetic --data out/synthetic_predictor/data --group-mode average
    gpgraph predict --checkpoint gpgraph-stgcnn-hotel --history out/hist.npy --out out/pred.npz
    gpgraph interpolate --start gpgraph-stgcnn-synthetic-conv --end runs/hotel/best.pt --alpha 0.5 \
        --out runs/hotel-wise50.pt
    gpgraph groups --groups ../shared/datasets/eth_ucy_groups --group-overlaps merge --absent-ids drop \
        --predictor gpgraph-stgcnn-synthetic --predictor 'gpgraph-stgcnn-{scene}+coherent-motion'
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace
from functools import partial
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import torch

from predictor.checkpoint import CheckpointError, load_model
from predictor.data import DataFormatError
from predictor.device import DEVICES, resolve_device
from predictor.ethucy import DEFAULT_DATA_DIR, GROUP_OVERLAPS, OBS_LEN
from predictor.evaluate import EvalConfig, evaluate
from predictor.files import write_atomic
from predictor.group_rules import GROUP_RULES, get_rule
from predictor.group_validation import ABSENT_IDS
from predictor.grouping import THRESHOLD_MODES
from predictor.model import ASSIGNERS, GPGraph, GPGraphConfig, check_group_threshold_scale
from predictor.names import flag_values, long_options, os_error_line, parser_hint
from predictor.sampling import PROTOCOLS
from predictor.train import TrainConfig, initial_weights, train
from predictor.train_split import train_val_windows
from predictor.windows import load_windows

METRIC_KEYS = ("ade", "fde", "col", "tcc", "pw_precision", "pw_recall", "gmitre_precision", "gmitre_recall")
SPLITS = ("train", "val", "test")


def split_folder(data: Path, split: str) -> Path:
    """``data/split`` when it exists, else ``data`` itself (a folder of trajectory files)."""
    sub = data / split
    return sub if sub.is_dir() else data


def _windows(data: Path, split: str) -> list:
    folder = split_folder(data, split)
    windows = load_windows(folder)
    if not windows:
        raise ValueError(f"no windows with >= 2 pedestrians present for 20 steps in {folder}")
    return windows


def cmd_train(args: argparse.Namespace) -> int:
    _check_output_dir(args.out)
    if args.resume and not (Path(args.out) / "last.pt").is_file():
        raise ValueError(f"--resume: nothing to resume, {Path(args.out) / 'last.pt'} does not exist")
    model_cfg = GPGraphConfig.backbone_only(args.backbone) if args.no_groups else GPGraphConfig(
        backbone=args.backbone, grouping=args.grouping, bce_weight=args.bce_weight, assigner=args.assigner)
    cfg = TrainConfig(epochs=args.epochs, batch_size=args.batch_size, lr=args.lr, rotate=args.rotate,
                      bucket=args.bucket, max_pairs=args.max_pairs,
                      seed=args.seed, eval_every=args.eval_every, init=args.init,
                      val_fraction=args.val_fraction, model=model_cfg)
    if args.init:  # a missing, corrupt or mismatched checkpoint is reported before any data is read
        initial_weights(GPGraph(model_cfg), args.init)
    train_w, val_w, val_source = train_val_windows(args.data, args.val_fraction)
    train_w, val_w = train_w[: args.max_windows or None], val_w[: args.max_windows or None]
    labelled = sum(w.group_id is not None for w in train_w)
    print(f"{len(train_w)} training / {len(val_w)} validation windows (validation: {val_source}); group labels "
          f"in {labelled} of the training windows", flush=True)
    if args.bce_weight > 0 and labelled == 0:
        raise ValueError(f"--bce-weight {args.bce_weight} needs group labels (X.groups.txt or X.labels.tsv beside "
                         f"the trajectory files), and {split_folder(args.data, 'train')} has none")
    summary = train(cfg, train_w, val_w, args.out, resume=args.resume, progress=not args.quiet, device=args.device)
    if summary["val_ade"] is not None:
        print(f"last validation ADE/FDE (iid, best of 20) {summary['val_ade']:.4f} / {summary['val_fde']:.4f} m")
    print(f"best validation loss {summary['best_val']:.4f}; {summary['seconds']:.1f} s; "
          f"checkpoint {Path(args.out) / 'best.pt'} (kept by validation loss); log {Path(args.out) / 'log.csv'}")
    return 0


def format_table(result: dict) -> str:
    """A two-row text table of the metrics present in ``result``."""
    keys = [k for k in METRIC_KEYS if k in result]
    head = " ".join(f"{k:>16}" for k in keys)
    row = " ".join(f"{result[k]:>16.4f}" for k in keys)
    return f"protocol={result['protocol']} seed={result['seed']} trials={result['trials']}\n{head}\n{row}"


def _check_window_rule(model: Any) -> None:
    """evaluate and predict have 8 observed steps per pedestrian: a group rule that reads a longer track would
    silently read less than it is for."""
    if model.group_rule is not None and (steps := get_rule(model.group_rule).track_steps) > OBS_LEN:
        raise ValueError(f"group rule {model.group_rule} reads {steps} positions per pedestrian, and this command has "
                         f"the {OBS_LEN} observed steps only (gpgraph groups and the env give rules their tracks)")


def cmd_evaluate(args: argparse.Namespace) -> int:
    if args.json:
        _check_output_file(args.json, ".json")
    model, _ = load_model(args.checkpoint, backbone=args.backbone, grouping=args.grouping,
                          group_threshold_scale=args.group_threshold_scale, group_mode=args.group_mode,
                          group_rule=args.group_rule)
    _check_window_rule(model)
    windows = _windows(args.data, args.split)
    cfg = EvalConfig(protocol=args.protocol, seed=args.seed, trials=args.trials, n_samples=args.samples,
                     pool_size=args.pool_size)
    result = evaluate(model.to(args.device), windows, cfg, progress=not args.quiet)
    result["checkpoint"] = str(args.checkpoint)
    result["grouping"] = model.config.grouping
    result["group_threshold_scale"] = model.group_threshold_scale
    result["group_mode"] = model.effective_group_mode
    result["group_rule"] = model.group_rule
    result["split"] = args.split
    print(format_table(result))
    if args.json:
        clean = {k: (None if isinstance(v, float) and v != v else v) for k, v in result.items()}  # NaN -> null
        text = json.dumps(clean, indent=2, allow_nan=False) + "\n"
        write_atomic(args.json, lambda tmp: Path(tmp).write_text(text))
    return 0


def cmd_predict(args: argparse.Namespace) -> int:
    from predictor.api import GPGraphPredictor

    out = _check_output_file(args.out, ".npz")
    history = _load_history(args.history)
    model, _ = load_model(args.checkpoint, backbone=args.backbone, grouping=args.grouping,
                          group_threshold_scale=args.group_threshold_scale, group_mode=args.group_mode,
                          group_rule=args.group_rule)
    _check_window_rule(model)
    model = model.to(args.device)
    if args.sample_level:
        model.config = replace(model.config, sample_level=args.sample_level)
    pred = GPGraphPredictor(model).predict(history, n_samples=args.samples, rng=np.random.default_rng(args.seed))
    def write(tmp: str) -> None:
        with open(tmp, "wb") as fh:  # a file handle: numpy writes exactly here (a path would gain ".npz")
            np.savez(fh, samples=pred.samples, mean=pred.mean, cov=pred.cov, group_id=pred.group_id)
    write_atomic(out, write)
    print(f"wrote {out}: samples {pred.samples.shape}, groups {pred.group_id.tolist()}")
    return 0


def cmd_interpolate(args: argparse.Namespace) -> int:
    """Write (1 - alpha) * start + alpha * end (predictor.interpolate, WiSE-FT) as a checkpoint file."""
    from predictor.interpolate import interpolate_checkpoints

    out = _check_output_file(args.out, ".pt")
    meta = interpolate_checkpoints(args.start, args.end, args.alpha, out)  # checks alpha before reading anything
    print(f"wrote {out}: (1 - {args.alpha}) * {args.start} + {args.alpha} * {args.end} "
          f"(epoch of end: {meta.get('epoch')})")
    return 0


GROUP_TABLE_KEYS = ("pw_precision", "pw_recall", "pw_f1", "gmitre_precision", "gmitre_recall", "gmitre_f1")


def cmd_groups(args: argparse.Namespace) -> int:
    """PW / G-MITRE of each --predictor's groups on every window of the annotated recordings (validation)."""
    from predictor.api import load_predictor
    from predictor.group_validation import read_annotations, validate
    from predictor.windows import window_tracks

    if args.json:
        _check_output_file(args.json, ".json")
    recordings = read_annotations(args.data, args.groups, args.group_overlaps, args.absent_ids)
    loaded: dict[str, Any] = {}

    def load(name: str) -> Any:
        if name not in loaded:
            loaded[name] = load_predictor(name)
        return loaded[name]

    def groups_by(spec: str, rec: Any) -> Any:
        predictor = load(spec.replace("{scene}", rec.scene))
        if not predictor.reads_track:
            return lambda w: predictor.predict(w.obs, n_samples=1, rng=0).group_id
        # a rule that reads a longer past gets each window's from the recording (NaN before a person was first seen)
        tracks = {id(w): t for w, t in zip(rec.windows, window_tracks(rec.rows, rec.windows, predictor.track_steps),
                                            strict=True)}
        return lambda w: predictor.predict(w.obs, n_samples=1, rng=0, track=tracks[id(w)]).group_id

    for spec in args.predictor:
        load(spec.replace("{scene}", recordings[0].scene))  # a bad name fails before any scoring or note
    for rec in recordings:
        for note in rec.notes:
            print(f"note: {note}", file=sys.stderr)
    results = {}
    print(f"{'predictor':<44} {'recording':<14} {'windows':>7} " + " ".join(f"{k:>16}" for k in GROUP_TABLE_KEYS))
    for spec in args.predictor:
        results[spec] = validate(recordings, partial(groups_by, spec))
        for rec_name, r in results[spec].items():
            cells = " ".join(f"{r[k]:>16.3f}" for k in GROUP_TABLE_KEYS)
            print(f"{spec:<44} {rec_name:<14} {r['windows']:>7} {cells}")
    if args.json:
        payload = {"data": str(args.data), "groups": str(args.groups), "group_overlaps": args.group_overlaps,
                   "absent_ids": args.absent_ids, "notes": [n for r in recordings for n in r.notes],
                   "results": results}
        text = json.dumps(payload, indent=2, allow_nan=True) + "\n"
        write_atomic(args.json, lambda tmp: Path(tmp).write_text(text))
    return 0


def cmd_list(args: argparse.Namespace) -> int:
    """The packaged checkpoints and the model-free baseline: one line each, the name (what --checkpoint and
    load_predictor take) then what it is, from the checkpoint's own metadata (`predictor.catalog`)."""
    from predictor.api import CONSTANT_VELOCITY_NAMES
    from predictor.catalog import catalog

    rows = catalog()
    assert rows[-1][0] == CONSTANT_VELOCITY_NAMES[0]
    width = max(len(name) for name, _ in rows)
    for name, text in rows:
        print(f"{name:<{width}}  {text}")
    return 0


def _check_output_dir(path: Path) -> None:
    """ValueError unless `path` is, or can be created as, a folder (no file on the way); creates nothing."""
    for p in (Path(path), *Path(path).parents):
        if p.exists():
            if not p.is_dir():
                raise ValueError(f"output {path}: {p} is a file, not a folder")
            return


def _check_output_file(path: Path, suffix: str) -> Path:
    """`path` if it names a file ending in `suffix` that can be written; ValueError otherwise (creates nothing)."""
    path = Path(path)
    if path.suffix != suffix:
        raise ValueError(f"output {path}: the file name must end in {suffix}")
    if path.is_dir():
        raise ValueError(f"output {path} is a folder; give a file name")
    _check_output_dir(path.parent)
    return path


def _load_history(path: Path) -> np.ndarray:
    """An (8, N, 2) float history from a numpy .npy file; ValueError naming the file otherwise."""
    if not Path(path).is_file():
        raise ValueError(f"--history {path}: no such file (expected a numpy .npy array of shape (8, N, 2), metres)")
    try:
        history = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError):
        raise ValueError(f"--history {path}: not a numpy .npy array file; save one with numpy.save "
                         "(shape (8, N, 2), metres)") from None
    if not isinstance(history, np.ndarray) or history.ndim != 3 or history.shape[2] != 2:
        raise ValueError(f"--history {path}: expected shape (8, N, 2), got "
                         f"{getattr(history, 'shape', type(history).__name__)}")
    return history


def group_threshold_scale_arg(text: str) -> float:
    """argparse type of --group-threshold-scale: a finite number > 0 (else a one-line usage error, exit 2)."""
    try:
        return check_group_threshold_scale(float(text))
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}") from None


def _group_calibration(p: argparse.ArgumentParser) -> None:
    p.add_argument("--group-threshold-scale", type=group_threshold_scale_arg, default=None, metavar="X",
                   help="multiply the learned group threshold pi by X at inference (below 1: fewer, smaller "
                        "groups); None: the checkpoint's calibrated value, else 1.0 (the learned pi as is)")
    p.add_argument("--group-mode", choices=THRESHOLD_MODES, default=None, metavar="NAME",
                   help=f"hard grouping at inference, one of {', '.join(THRESHOLD_MODES)} ('average': average-"
                        "linkage clustering of the learned distances cut at the threshold); None: the "
                        "checkpoint's, else the grouping it was trained with")
    p.add_argument("--group-rule", choices=tuple(GROUP_RULES), default=None, metavar="NAME",
                   help=f"replace the learned hard grouping by a rule on the observed positions, one of "
                        f"{', '.join(GROUP_RULES)} (predictor.group_rules); None: the learned grouping")


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    p.add_argument("--device", choices=DEVICES, default="cpu",
                   help="where the model runs: auto = cuda when torch sees a GPU, else cpu (sampling stays on "
                        "the CPU, checkpoints hold CPU tensors)")
    p.add_argument("--backbone", default=None, help="backbone name (sgcn, stgcnn); default: train stgcnn, "
                   "evaluate/predict the checkpoint's own")
    p.add_argument("--grouping", default=None, choices=["exact", "official", "ratio"],
                   help="hard groups from the learned pair distances: exact (connected components of the pairs within "
                        "the threshold), official (the reference code's relabelling), ratio (fixed-ratio ablation); "
                        "default: train exact, evaluate/predict the checkpoint's own")


class OneLineParser(argparse.ArgumentParser):  # the same conventions as crowdsim.cli (no cross-package import)
    """Argument errors as one line on stderr (`prog command: error: ...`, exit 2), without the usage block
    (`--help` still shows it). Options must be spelt out in full: no abbreviations."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def parse_known_args(self, args: Any = None, namespace: Any = None) -> Any:
        self.typed = list(sys.argv[1:] if args is None else args)  # what error() compares with the valid flags
        return super().parse_known_args(args, namespace)

    def error(self, message: str) -> NoReturn:
        hint = parser_hint(message, long_options(self), getattr(self, "typed", ()))
        self.exit(2, f"{self.prog}: error: {hint}\n")


def show_defaults(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Make `--help` print every option's default: options without help text get their name as help, which
    `ArgumentDefaultsHelpFormatter` completes with "(default: ...)". Returns the parser."""
    parser.formatter_class = argparse.ArgumentDefaultsHelpFormatter
    for action in parser._actions:
        if action.option_strings and action.help is None and action.default is not argparse.SUPPRESS:
            action.help = action.dest.replace("_", " ")
    return parser


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="gpgraph", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    t = sub.add_parser("train", help="train on DATA/train, select by DATA/val loss (or a held-out --val-fraction)")
    _common(t)
    t.add_argument("--data", type=Path, required=True,
                   help="a split folder with train/ and val/ ETH/UCY files, e.g. ../shared/datasets/eth_ucy/eth "
                        "(or a folder of files with --val-fraction)")
    t.add_argument("--out", type=Path, required=True,
                   help="run folder: best.pt (lowest validation loss), last.pt (for --resume), log.csv")
    t.add_argument("--no-groups", action="store_true", help="the backbone alone (no GP-Graph branches)")
    t.add_argument("--epochs", type=int, default=TrainConfig.epochs, help="passes over the training windows")
    t.add_argument("--batch-size", type=int, default=TrainConfig.batch_size, help="windows per optimiser step")
    t.add_argument("--lr", type=float, default=TrainConfig.lr,
                   help="Adam learning rate (halved at epochs 50 and 100)")
    t.add_argument("--bucket", type=int, default=TrainConfig.bucket, help="size-sorting chunk, in batches")
    t.add_argument("--max-pairs", type=int, default=None,
                   help="micro-batch budget B * N_max^2 (0: one pass per batch; default: the backbone's)")
    t.add_argument("--bce-weight", type=float, default=0.0, help="GP-Graph+S BCE weight (needs labels)")
    t.add_argument("--rotate", action="store_true", help="random rotation augmentation")
    t.add_argument("--assigner", choices=ASSIGNERS, default="conv",
                   help="pair distance D: conv (GP-Graph's F_phi) or pairwise (predictor.pair_assigner)")
    t.add_argument("--seed", type=int, default=0, help="initial weights, batch order and latent draws")
    t.add_argument("--val-fraction", type=float, default=None, metavar="F",
                   help="for DATA without a val/ folder: validate on the last F (0 < F <= 0.5) of each recording's "
                        "frames and train on the rest (no window crosses the cut); without it such DATA is an "
                        "error (default: DATA/val)")
    t.add_argument("--max-windows", type=int, default=0,
                   help="use only the first N training and N validation windows (a quick check: 512 windows and "
                        "--epochs 5 take under a minute; 0: all)")
    t.add_argument("--resume", action="store_true", help="continue from OUT/last.pt")
    t.add_argument("--init", default="", metavar="CHECKPOINT",
                   help="start from this checkpoint's weights (packaged name or path; same architecture), e.g. "
                        "fine-tune gpgraph-stgcnn-synthetic on real data; default: random weights")
    t.add_argument("--eval-every", type=int, default=TrainConfig.eval_every,
                   help="validation ADE/FDE (iid, best of 20, 1 trial, seed 0) at epochs 0, N, 2N, ... and the "
                        "last, into log.csv columns val_ade,val_fde; 0: off (the checkpoint is kept by loss)")
    t.add_argument("--quiet", action="store_true", help="no progress bar")
    t.set_defaults(func=cmd_train)
    e = sub.add_parser("evaluate", help="ADE/FDE/COL/TCC (+ PW/G-MITRE) on DATA/test (or --split)")
    _common(e)
    e.add_argument("--checkpoint", required=True, help="checkpoint path or packaged name")
    e.add_argument("--data", type=Path, required=True, help="a split folder (or a folder of ETH/UCY files)")
    e.add_argument("--split", choices=SPLITS, default="test",
                   help="which DATA/SPLIT folder to score (DATA itself when it has no such folder)")
    _group_calibration(e)
    e.add_argument("--protocol", choices=PROTOCOLS, default="iid",
                   help="iid: independent latent draws; paper: the published code's KMeans-spread group latents")
    e.add_argument("--seed", type=int, default=0, help="seeds the latent draws of all trials")
    e.add_argument("--trials", type=int, default=EvalConfig.trials, help="repeats averaged (best-of-K each)")
    e.add_argument("--samples", type=int, default=EvalConfig.n_samples, help="K of best-of-K ADE/FDE")
    e.add_argument("--pool-size", type=int, default=EvalConfig.pool_size,
                   help="KMeans latent sets precomputed for --protocol paper")
    e.add_argument("--json", type=Path, default=None, help="also write the metrics to this JSON file")
    e.add_argument("--quiet", action="store_true", help="no progress bar")
    e.set_defaults(func=cmd_evaluate)
    r = sub.add_parser("predict", help="sample futures for an (8, N, 2) history saved with numpy")
    _common(r)
    r.add_argument("--checkpoint", required=True, help="checkpoint path or packaged name")
    r.add_argument("--history", type=Path, required=True, help=".npy file, shape (8, N, 2), metres")
    r.add_argument("--out", type=Path, required=True, help="output file, must end in .npz")
    r.add_argument("--samples", type=int, default=20, help="futures K per pedestrian")
    r.add_argument("--seed", type=int, default=0, help="latent draws")
    r.add_argument("--sample-level", choices=["group", "scene", "pedestrian"], default=None,
                   help="one latent per group (GP-Graph), per scene or per pedestrian; default: the model's")
    _group_calibration(r)
    r.set_defaults(func=cmd_predict)
    i = sub.add_parser("interpolate", help="weights (1 - alpha) * START + alpha * END of a pretrained model and its "
                       "fine-tuned copy (WiSE-FT; predictor.interpolate), written as a checkpoint")
    i.add_argument("--start", required=True, metavar="CHECKPOINT",
                   help="the pretrained model (packaged name or path), e.g. gpgraph-stgcnn-synthetic-conv")
    i.add_argument("--end", required=True, metavar="CHECKPOINT",
                   help="the same architecture fine-tuned from START (its config, grouping and meta are kept)")
    i.add_argument("--alpha", type=float, required=True, help="0: START's weights, 1: END's (a number in [0, 1])")
    i.add_argument("--out", type=Path, required=True, help="output checkpoint, must end in .pt")
    i.set_defaults(func=cmd_interpolate)
    g = sub.add_parser("groups", help="grouping on real annotated people (validation): PW and G-MITRE of each "
                       "predictor's groups on every window of the recordings that GROUPS annotates")
    g.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    g.add_argument("--data", type=Path, default=DEFAULT_DATA_DIR,
                   help="ETH/UCY data; the recording X.txt of GROUPS/X.groups.txt is DATA/*/test/X.txt")
    g.add_argument("--groups", type=Path, required=True, help="folder of X.groups.txt annotations")
    g.add_argument("--predictor", action="append", required=True, metavar="NAME",
                   help="predictor name or checkpoint, repeatable; '{scene}' becomes each recording's scene "
                        "(e.g. gpgraph-stgcnn-{scene}, its leave-one-out model); NAME+RULE groups by a rule of "
                        "predictor.group_rules (constant-velocity+RULE: the rule alone)")
    g.add_argument("--group-overlaps", choices=GROUP_OVERLAPS, default="error",
                   help="a pedestrian listed on two lines: error, or merge those groups (each merge noted)")
    g.add_argument("--absent-ids", choices=ABSENT_IDS, default="error",
                   help="a listed pedestrian the recording lacks: error, or drop it (noted)")
    g.add_argument("--json", type=Path, default=None)
    g.set_defaults(func=cmd_groups)
    ls = sub.add_parser("list", help="the packaged predictors, one a line: the name (usable wherever a checkpoint "
                        "is asked for) and what it is (model, grouping, training data, validation loss, role)")
    ls.set_defaults(func=cmd_list)
    for command in sub.choices.values():
        show_defaults(command)
    return parser


def main(argv: list[str] | None = None) -> int:
    """The ``gpgraph`` entry point: exit 0, 2 on misuse (one line on stderr), 130 on Ctrl-C (one line: what was
    kept; an interrupted ``train`` resumes with ``--resume``)."""
    try:
        return _main(argv)
    except KeyboardInterrupt as exc:
        print(f"gpgraph: interrupted{': ' + str(exc) if str(exc) else ''}", file=sys.stderr)
        return 130


def _main(argv: list[str] | None) -> int:
    args = build_parser().parse_args(argv)
    if args.command == "list":
        return cmd_list(args)
    threads = getattr(args, "threads", 1)  # interpolate has no --threads (nothing to compute in parallel)
    if threads < 1:
        print("gpgraph: error: --threads must be >= 1", file=sys.stderr)
        return 2
    torch.set_num_threads(threads)
    try:
        if hasattr(args, "device"):  # groups runs on the CPU
            args.device = resolve_device(args.device)  # before anything is read or written
    except ValueError as exc:
        print(f"gpgraph: error: {exc}", file=sys.stderr)
        return 2
    if args.command == "train" and args.backbone is None:
        args.backbone = "stgcnn"
    if args.command == "train" and args.grouping is None:
        args.grouping = "exact"
    try:
        return args.func(args)
    except (CheckpointError, DataFormatError, FileNotFoundError, ValueError) as exc:
        message = os_error_line(exc, flag_values(args)) if isinstance(exc, OSError) else exc
        print(f"gpgraph: error: {message}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
