"""Batched training: many padded windows per forward pass, NLL (+ optional GP-Graph+S BCE) loss.

Checkpoints (written atomically, config inside): ``best.pt`` (lowest validation loss, what evaluation
uses) and ``last.pt`` (model, optimiser, scheduler, epoch and rng state, for ``resume``), always with CPU
tensors whatever the training device. One row per epoch goes to ``log.csv`` (``LOG_FIELDS``): losses, the
learning rate, seconds, and every ``eval_every`` epochs the validation best-of-20 ADE/FDE (m) of the 'iid'
protocol (one trial, seed ``VAL_EVAL_SEED``), empty on the other epochs. The checkpoint is still selected
by the validation loss alone. Ctrl-C raises ``TrainInterrupted``, whose message says which epoch last.pt holds;
``resume`` continues from the next.
"""

from __future__ import annotations

import csv
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import Tensor
from tqdm import tqdm

from predictor.backbones import BACKBONES
from predictor.batch import Batch, collate
from predictor.checkpoint import FORMAT, META_STEP_S, load_state, read_file, save_atomic, save_model
from predictor.device import model_device
from predictor.ethucy import STEP_S
from predictor.evaluate import EvalConfig, evaluate
from predictor.files import write_atomic
from predictor.gaussian import masked_nll
from predictor.grouping import pair_mask
from predictor.model import GPGraph, GPGraphConfig
from predictor.train_split import check_val_fraction
from predictor.windows import Window, augment_rotations

LOG_FIELDS = ("epoch", "train_loss", "val_loss", "lr", "seconds", "val_ade", "val_fde")
VAL_EVAL_SEED = 0  # latent draws of the periodic validation ADE/FDE: the same every time, so epochs compare


@dataclass(frozen=True)
class TrainConfig:
    """Training recipe; the defaults are the reference recipe (Adam, 300 epochs, batch 128 windows).

    Attributes:
        epochs: passes over the training windows.
        batch_size: windows per optimiser step (and per forward pass).
        lr: Adam learning rate; weight_decay: L2 weight decay.
        milestones: epochs at which the learning rate is multiplied by ``gamma``.
        clip_grad: gradient-norm clip.
        rotate: random rotation augmentation of training windows.
        bucket: batches drawn from chunks of ``bucket * batch_size`` shuffled windows sorted by size
            (less padding); 1 disables sorting.
        max_pairs: split each optimiser batch into size-sorted micro-batches of at most this many
            padded pair slots (B * N_max^2), accumulating gradients; 0 disables splitting; None uses the
            backbone's ``pair_budget`` (measured fastest on CPU).
        seed: seeds the numpy Generator (shuffling, rotations) and the initial weights.
        eval_every: validation ADE/FDE at epochs 0, N, 2N, ... and the last (0: never); does not affect
            which checkpoint is kept.
        init: a checkpoint (packaged name or path) whose weights start the training instead of random ones
            (fine-tuning, e.g. from a crowdsim-trained model); its architecture must equal ``model``'s (loss
            weights such as ``bce_weight`` may differ); "" = random initial weights.
        val_fraction: where the validation windows came from, recorded with the checkpoints: None = the data's
            own val/ split; F = the last F of each recording's frames (``predictor.train_split``).
    """

    epochs: int = 300
    batch_size: int = 128
    lr: float = 0.01
    weight_decay: float = 1e-4
    milestones: tuple[int, ...] = (50, 100)
    gamma: float = 0.5
    clip_grad: float = 10.0
    rotate: bool = False
    bucket: int = 8
    max_pairs: int | None = None
    seed: int = 0
    eval_every: int = 10
    init: str = ""
    val_fraction: float | None = None
    model: GPGraphConfig = field(default_factory=GPGraphConfig)

    def __post_init__(self) -> None:
        if self.epochs < 1 or self.batch_size < 1 or self.bucket < 1 or (self.max_pairs or 0) < 0:
            raise ValueError("epochs, batch_size and bucket must be >= 1 and max_pairs >= 0")
        if self.eval_every < 0:
            raise ValueError(f"eval_every must be >= 0 (0: off), got {self.eval_every}")
        if self.val_fraction is not None:
            check_val_fraction(self.val_fraction)
        if self.lr <= 0 or self.weight_decay < 0 or self.clip_grad <= 0 or not 0 < self.gamma <= 1:
            raise ValueError("need lr > 0, weight_decay >= 0, clip_grad > 0 and 0 < gamma <= 1")

    @property
    def pair_budget(self) -> int:
        """The micro-batch budget in effect."""
        return BACKBONES[self.model.backbone].pair_budget if self.max_pairs is None else self.max_pairs

    def to_dict(self) -> dict:
        d = asdict(self)
        d["milestones"] = list(self.milestones)
        return d

    def evaluates_at(self, epoch: int) -> bool:
        """Whether epoch ``epoch`` (0-based, as in log.csv) computes the validation ADE/FDE."""
        return self.eval_every > 0 and (epoch % self.eval_every == 0 or epoch == self.epochs - 1)


def split_by_size(windows: list[Window], max_pairs: int) -> list[list[Window]]:
    """Sort by pedestrian count and cut into micro-batches whose padded size B * N_max^2 <= ``max_pairs``.

    Each micro-batch holds at least one window; ``max_pairs`` 0 keeps everything in one batch.
    """
    if max_pairs <= 0:
        return [windows]
    out: list[list[Window]] = []
    for w in sorted(windows, key=lambda w: w.n_peds):
        if out and (len(out[-1]) + 1) * w.n_peds**2 <= max_pairs:
            out[-1].append(w)
        else:
            out.append([w])
    return out


def make_batches(
    windows: list[Window], batch_size: int, bucket: int, rng: np.random.Generator, max_pairs: int = 0
) -> list[list[Batch]]:
    """Optimiser steps, each a list of padded micro-batches.

    Shuffle, sort within chunks of ``bucket * batch_size`` windows by pedestrian count (``bucket`` 1: no
    sorting), cut into ``batch_size`` steps, shuffle the step order, then split each step by size.
    """
    order = rng.permutation(len(windows))
    chunk = batch_size * bucket
    groups: list[list[int]] = []
    for s in range(0, len(order), chunk):
        part = order[s : s + chunk].tolist()
        if bucket > 1:
            part = sorted(part, key=lambda i: windows[i].n_peds)
        groups += [part[j : j + batch_size] for j in range(0, len(part), batch_size)]
    steps = [[windows[i] for i in groups[j]] for j in rng.permutation(len(groups))]
    return [[collate(m) for m in split_by_size(step, max_pairs)] for step in steps]


def group_bce(dist: Tensor, pi: Tensor, tau: float, batch: Batch) -> Tensor:
    """GP-Graph+S: BCE between sigmoid(-(D - pi) / tau) and same-group labels over real pairs i != j."""
    gt = batch.gt_groups
    n = dist.shape[1]
    valid = pair_mask(batch.node_mask) & ~torch.eye(n, dtype=torch.bool, device=dist.device)[None]
    logits = -(dist - pi) / tau
    target = (gt[:, :, None] == gt[:, None, :]).to(dist.dtype)
    loss = torch.nn.functional.binary_cross_entropy_with_logits(logits, target, reduction="none")
    return (loss * valid).sum() / valid.sum().clamp_min(1)


def batch_loss(model: GPGraph, batch: Batch) -> Tensor:
    """Mean NLL over windows, plus bce_weight * BCE when the batch carries group labels.

    ``batch`` must be on the model's device (``Batch.to``).
    """
    out = model(batch.obs_abs, batch.obs_rel, batch.node_mask)
    loss = masked_nll(out.raw, batch.pred_rel, batch.node_mask)
    w = model.config.bce_weight
    if w > 0 and batch.gt_groups is not None:
        loss = loss + w * group_bce(out.dist, out.pi, model.config.tau, batch)
    return loss


def eval_batches(windows: list[Window], batch_size: int, max_pairs: int) -> list[Batch]:
    """Size-sorted batches of at most ``batch_size`` windows and ``max_pairs`` padded pair slots (0: no
    pair limit), for passes without gradients: the window-weighted loss does not depend on the grouping."""
    parts = split_by_size(windows, max_pairs) if max_pairs > 0 else [sorted(windows, key=lambda w: w.n_peds)]
    return [collate(p[i : i + batch_size]) for p in parts for i in range(0, len(p), batch_size)]


@torch.no_grad()
def validation_loss(model: GPGraph, batches: list[Batch]) -> float:
    """Window-weighted mean loss over ``batches`` (moved to the model's device)."""
    model.eval()
    device = model_device(model)
    total = sum(batch_loss(model, b.to(device)).item() * b.node_mask.shape[0] for b in batches)
    return total / sum(b.node_mask.shape[0] for b in batches)


def _optimiser(model: GPGraph, cfg: TrainConfig) -> tuple[torch.optim.Optimizer, torch.optim.lr_scheduler.LRScheduler]:
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    sched = torch.optim.lr_scheduler.MultiStepLR(opt, milestones=list(cfg.milestones), gamma=cfg.gamma)
    return opt, sched


def train_epoch(model: GPGraph, steps: list[list[Batch]], opt: torch.optim.Optimizer, clip: float) -> float:
    """One pass over optimiser steps (micro-batches accumulate, weighted by their window count).

    Batches are moved to the model's device. Returns the window-weighted mean training loss.
    """
    model.train()
    device = model_device(model)
    total, count = 0.0, 0
    for micro in steps:
        opt.zero_grad(set_to_none=True)
        n_step = sum(b.node_mask.shape[0] for b in micro)
        for b in micro:
            n = b.node_mask.shape[0]
            loss = batch_loss(model, b.to(device))
            (loss * (n / n_step)).backward()
            total += loss.item() * n
        count += n_step
        torch.nn.utils.clip_grad_norm_(model.parameters(), clip)
        opt.step()
    return total / count


def _resume(out: Path, model: GPGraph, opt, sched, rng: np.random.Generator) -> tuple[int, float]:
    """Restore state from ``out/last.pt``; returns (next epoch, best validation loss)."""
    state = read_file(out / "last.pt")
    load_state(model, state["state_dict"], str(out / "last.pt"))
    opt.load_state_dict(state["optimizer"])
    sched.load_state_dict(state["scheduler"])
    rng.bit_generator.state = state["rng"]
    return int(state["epoch"]) + 1, float(state["best_val"])


def validation_ade_fde(model: GPGraph, windows: list[Window]) -> tuple[float, float]:
    """Best-of-20 ADE and FDE (m) of the 'iid' protocol, one trial, seed ``VAL_EVAL_SEED`` (deterministic)."""
    res = evaluate(model, windows, EvalConfig(protocol="iid", seed=VAL_EVAL_SEED, trials=1, n_samples=20),
                   ade_fde_only=True)
    return res["ade"], res["fde"]


def _start_log(path: Path, start: int) -> None:
    """Write the header of a new ``log.csv`` (``start`` 0); on resume at epoch ``start``, drop the rows of epochs
    >= ``start`` (logged by a run stopped before its last.pt was saved) and upgrade a log with fewer columns (an
    older version's) to ``LOG_FIELDS``, its old rows padded with empty cells."""
    if start == 0 or not path.is_file():
        path.write_text(",".join(LOG_FIELDS) + "\n")
        return
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    kept = [r for r in rows[1:] if r and r[0].isdigit() and int(r[0]) < start]
    if rows and (tuple(rows[0]) != LOG_FIELDS or len(kept) != len(rows) - 1):
        rows = rows[:1] + kept
        width = len(LOG_FIELDS)

        def write(tmp: str) -> None:
            with open(tmp, "w", newline="") as f:
                csv.writer(f).writerows([list(LOG_FIELDS)] + [r + [""] * (width - len(r)) for r in rows[1:]])
        write_atomic(path, write)


LOSS_ONLY_FIELDS = ("bce_weight",)  # GPGraphConfig fields that change the loss, not the weights' layout


def initial_weights(model: GPGraph, init: str) -> None:
    """Load the weights of checkpoint ``init`` into ``model`` (ValueError naming the differing architecture
    fields when they do not match)."""
    from predictor.checkpoint import load_model

    source, _ = load_model(init)
    diff = architecture_differences(source.config, model.config, "(init)")
    if diff:
        raise ValueError(f"--init {init}: architecture differs: {diff}")
    model.load_state_dict(source.state_dict())


def architecture_differences(a: GPGraphConfig, b: GPGraphConfig, a_label: str = "") -> str:
    """'' when ``a`` and ``b`` lay out the same weights (every field but LOSS_ONLY_FIELDS equal), else the differing
    fields as "name A_value[ a_label] vs B_value, ..."."""
    mine = {k: v for k, v in b.to_dict().items() if k not in LOSS_ONLY_FIELDS}
    theirs = {k: v for k, v in a.to_dict().items() if k not in LOSS_ONLY_FIELDS}
    label = f" {a_label}" if a_label else ""
    return ", ".join(f"{k} {theirs.get(k)!r}{label} vs {mine.get(k)!r}" for k in sorted(set(mine) | set(theirs))
                     if mine.get(k) != theirs.get(k))


class TrainInterrupted(KeyboardInterrupt):
    """Ctrl-C during ``train``; ``str()`` says in one line what was kept and how to continue. Still a
    KeyboardInterrupt, so code that stops on Ctrl-C keeps doing so."""


def interrupted_message(out: Path) -> str:
    """What an interrupted run left in ``out``, from its last.pt (the last complete epoch, if any)."""
    if not (out / "last.pt").is_file():
        return f"no epoch completed, nothing to resume in {out}; rerun the command to start again"
    last_done = int(read_file(out / "last.pt")["epoch"])
    return (f"epochs up to {last_done} saved in {out / 'last.pt'} (best.pt: the lowest validation loss so far); "
            f"rerun the command with --resume to continue at epoch {last_done + 1}")


def _run_epoch(cfg: TrainConfig, model: GPGraph, opt, sched, rng: np.random.Generator, train_windows: list[Window],
               val_windows: list[Window], val_batches: list[Batch], out: Path, epoch: int, best: float,
               last_eval: tuple[float | None, float | None]) -> tuple[float, float | None, float | None, float, float]:
    """One epoch: train, validate, log, and save best.pt (when the validation loss improved) and then last.pt
    (the resumable state; a log row of an epoch without it is dropped on resume). Returns (best validation loss,
    the latest validation ADE and FDE, m, this epoch's training and validation losses)."""
    tic = time.perf_counter()
    windows = augment_rotations(train_windows, rng) if cfg.rotate else train_windows
    steps = make_batches(windows, cfg.batch_size, cfg.bucket, rng, cfg.pair_budget)
    tr = train_epoch(model, steps, opt, cfg.clip_grad)
    va = validation_loss(model, val_batches)
    ade, fde = last_eval
    evaluated = cfg.evaluates_at(epoch)
    if evaluated:
        ade, fde = validation_ade_fde(model, val_windows)
    lr = opt.param_groups[0]["lr"]
    sched.step()
    if va < best:
        best = va
        save_model(model, out / "best.pt", meta={"epoch": epoch, "val_loss": va, "train": cfg.to_dict(),
                                                 META_STEP_S: STEP_S})
    metrics = [f"{ade:.6f}", f"{fde:.6f}"] if evaluated else ["", ""]
    with (out / "log.csv").open("a", newline="") as f:
        csv.writer(f).writerow([epoch, f"{tr:.6f}", f"{va:.6f}", f"{lr:.6g}", f"{time.perf_counter() - tic:.2f}",
                                *metrics])
    save_atomic(
        {"format": FORMAT, "config": model.config.to_dict(), "state_dict": model.state_dict(),
         "optimizer": opt.state_dict(), "scheduler": sched.state_dict(), "epoch": epoch,
         "best_val": best, "rng": rng.bit_generator.state, "meta": {"train": cfg.to_dict(), META_STEP_S: STEP_S}},
        out / "last.pt",
    )
    return best, ade, fde, tr, va


def train(
    cfg: TrainConfig, train_windows: list[Window], val_windows: list[Window], out: str | Path,
    resume: bool = False, progress: bool = True, device: torch.device | str = "cpu",
) -> dict:
    """Train on ``device``, keeping ``best.pt`` by validation loss; returns a summary dict.

    The initial weights are drawn on the CPU (so every device starts from the same model) and then moved.
    Summary keys: best_val (loss), epochs, seconds, val_ade / val_fde (m, of the last evaluated epoch; None
    when ``cfg.eval_every`` is 0).
    """
    if not train_windows or not val_windows:
        raise ValueError("training needs at least one train and one val window (>= 2 pedestrians each)")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(cfg.seed)
    torch.manual_seed(cfg.seed)  # initial weights only; nothing random runs inside the model
    model = GPGraph(cfg.model)
    if cfg.init:
        initial_weights(model, cfg.init)
    model = model.to(device)
    opt, sched = _optimiser(model, cfg)
    start, best = (0, float("inf"))
    if resume and (out / "last.pt").is_file():
        start, best = _resume(out, model, opt, sched, rng)
    val_batches = [b.to(device) for b in eval_batches(val_windows, cfg.batch_size, cfg.pair_budget)]
    log_path = out / "log.csv"
    _start_log(log_path, start)
    t0 = time.perf_counter()
    ade = fde = None
    bar = tqdm(range(start, cfg.epochs), disable=not progress, desc="train", unit="epoch")
    try:
        for epoch in bar:
            best, ade, fde, tr, va = _run_epoch(cfg, model, opt, sched, rng, train_windows, val_windows,
                                                val_batches, out, epoch, best, (ade, fde))
            shown = {} if ade is None else {"ade": f"{ade:.3f}", "fde": f"{fde:.3f}"}  # the latest evaluation
            bar.set_postfix(train=f"{tr:.3f}", val=f"{va:.3f}", best=f"{best:.3f}", **shown)
    except KeyboardInterrupt:
        bar.close()
        raise TrainInterrupted(interrupted_message(out)) from None
    return {"best_val": best, "epochs": cfg.epochs, "seconds": time.perf_counter() - t0, "val_ade": ade,
            "val_fde": fde}
