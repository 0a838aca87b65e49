"""Tables for scripts/synthetic_pretraining.sh: ADE/FDE (m) per scene and variant, mean ± sd over seeds, the
five-scene average, and a paired comparison of `pretrain` against `real` over every (scene, seed) pair.

    python scripts/synthetic_pretraining_report.py out/synthetic_pretraining/eval

Reads `<variant>-<scene>-s<seed>-<protocol>.json` and `zeroshot[avg]-<scene>-<protocol>.json` (gpgraph evaluate).
The paired test is an exact two-sided sign test on the per-pair FDE difference (no normality assumed).
With two or more fine-tuning variants present for every scene (lr 0.01, 0.001, 0.0001, or none: zero-shot) it
also chooses the fine-tuning lr per scene by leave-one-scene-out (the other four scenes' test FDE), so that no
scene's choice sees its own test data, and prints the chosen family's five-scene average.

    python scripts/synthetic_pretraining_report.py best-seed out/synthetic_pretraining/val pretrainlow eth

prints the seed with the lowest validation FDE (the `validate` stage), which `package` ships.

    python scripts/synthetic_pretraining_report.py choose out/synthetic_pretraining/eval eth

prints the variant `package` ships for a scene: among the runs on disk (pretrainlow and the WiSE-FT wise<100a>, every
seed evaluated in every scene under both protocols), the one with the lowest mean of the iid and paper FDE over the
other four scenes (each protocol's mean over scenes and seeds first), so no scene's choice sees its own test data.
"""

from __future__ import annotations

import json
import re
import sys
from math import comb
from pathlib import Path

import numpy as np

SCENES = ("eth", "hotel", "univ", "zara1", "zara2")
WISE = tuple(f"wise{a}" for a in range(1, 100))  # (1 - a/100) * zero-shot + a/100 * pretrainlow (predictor.interpolate)
VARIANTS = ("real", "pretrain", "pretrainlow", "pretrainvlow", "zeroshot", "zeroshotavg", *WISE)
# lr 0.01, 0.001, 0.0001, none (lr 0), and the interpolations between none and 0.001
FINE_TUNED = ("pretrain", "pretrainlow", "pretrainvlow", "zeroshot", *WISE)
SHIPPABLE = ("pretrainlow", *WISE)  # variants with a checkpoint of their own under runs/
NAME = re.compile(r"^(real|pretrain|pretrainlow|pretrainvlow|zeroshot|zeroshotavg|wise\d\d?)-(\w+?)(?:-s(\d+))?"
                  r"-(iid|paper)$")


def load(folder: Path) -> dict[tuple[str, str, str], dict[int, tuple[float, float]]]:
    """(variant, scene, protocol) -> {seed: (ade, fde)}; zero-shot runs have seed -1."""
    out: dict[tuple[str, str, str], dict[int, tuple[float, float]]] = {}
    for path in sorted(folder.glob("*.json")):
        m = NAME.match(path.stem)
        if not m:
            continue
        variant, scene, seed, protocol = m.groups()
        d = json.loads(path.read_text())
        out.setdefault((variant, scene, protocol), {})[int(seed) if seed else -1] = (d["ade"], d["fde"])
    return out


def sign_test(diffs: np.ndarray) -> float:
    """Exact two-sided sign test p-value of the non-zero differences."""
    d = diffs[diffs != 0]
    n, k = len(d), int((d > 0).sum())
    if n == 0:
        return 1.0
    tail = sum(comb(n, i) for i in range(0, min(k, n - k) + 1)) / 2**n
    return min(1.0, 2 * tail)


def cell(values: dict[int, tuple[float, float]]) -> str:
    if not values:
        return "–"
    a = np.array(list(values.values()))
    if len(a) == 1:
        return f"{a[0, 0]:.3f}/{a[0, 1]:.3f}"
    return f"{a[:, 0].mean():.3f}±{a[:, 0].std(ddof=1):.3f} / {a[:, 1].mean():.3f}±{a[:, 1].std(ddof=1):.3f}"


def table(res: dict, protocol: str) -> list[str]:
    lines = [f"### Protocol {protocol}: ADE/FDE (m), mean ± sd over seeds", "",
             "| variant | " + " | ".join(SCENES) + " | average (seeds) |", "|---" * (len(SCENES) + 2) + "|"]
    for v in VARIANTS:
        if not any((v, s, protocol) in res for s in SCENES):
            continue
        row = [cell(res.get((v, s, protocol), {})) for s in SCENES]
        seeds = sorted(set.intersection(*[set(res.get((v, s, protocol), {})) for s in SCENES]))
        avg = "–"
        if seeds:
            per_seed = np.array([[np.mean([res[(v, s, protocol)][k][j] for s in SCENES]) for j in (0, 1)]
                                 for k in seeds])
            avg = f"{per_seed[:, 0].mean():.3f}/{per_seed[:, 1].mean():.3f} ({len(seeds)})"
        lines.append(f"| {v} | " + " | ".join(row) + f" | {avg} |")
    for variant in FINE_TUNED[:3]:
        pairs = [(res[(variant, s, protocol)][k][1], res[("real", s, protocol)][k][1]) for s in SCENES
                 for k in sorted(set(res.get((variant, s, protocol), {})) & set(res.get(("real", s, protocol), {})))]
        if pairs:
            d = np.array([p - r for p, r in pairs])
            lines += ["", f"{variant} - real FDE over {len(d)} (scene, seed) pairs: mean {d.mean():+.4f} m, "
                          f"{variant} better in {(d < 0).sum()}, worse in {(d > 0).sum()}; "
                          f"sign test p = {sign_test(d):.3g}"]
    return [*lines, ""]


def leave_one_scene_out(res: dict, protocol: str, candidates: tuple[str, ...]) -> list[str]:
    """Choose the fine-tuning lr for each scene without its test data: the candidate with the lowest mean test FDE
    over the other four scenes' splits (every seed; `zeroshot` = no fine-tuning). Then the chosen family's
    five-scene average (each scene: its chosen variant's mean over seeds) and, where `real` exists, the chosen
    variant against `real` on the scene itself, paired over (scene, seed)."""
    lines = [f"### Leave-one-scene-out choice of the fine-tuning lr, protocol {protocol}", "",
             "| scene | " + " | ".join(f"{v}: FDE on the other scenes" for v in candidates)
             + " | chosen | chosen ADE/FDE (seeds) |", "|---" * (len(candidates) + 3) + "|"]
    diffs, family = [], []
    for scene in SCENES:
        others = {v: float(np.mean([f for o in SCENES if o != scene for _, f in res[(v, o, protocol)].values()]))
                  for v in candidates}
        chosen = min(candidates, key=others.get)
        picked, real = res[(chosen, scene, protocol)], res.get(("real", scene, protocol), {})
        diffs += [picked[k][1] - real[k][1] for k in sorted(set(picked) & set(real))]
        ade, fde = np.mean([a for a, _ in picked.values()]), np.mean([f for _, f in picked.values()])
        family.append((ade, fde))
        lines.append(f"| {scene} | " + " | ".join(f"{others[v]:.3f}" for v in candidates) + f" | {chosen} | "
                     f"{ade:.3f}/{fde:.3f} ({len(picked)}) |")
    avg = np.mean(family, axis=0)
    lines += ["", f"the chosen family's five-scene average ADE/FDE: {avg[0]:.3f}/{avg[1]:.3f}"]
    if diffs:
        d = np.array(diffs)
        lines.append(f"chosen - real FDE over {len(d)} (scene, seed) pairs: mean {d.mean():+.4f} m, chosen better "
                     f"in {(d < 0).sum()}, worse in {(d > 0).sum()}; sign test p = {sign_test(d):.3g}")
    return [*lines, ""]


def best_seed(val_dir: Path, variant: str, scene: str) -> int:
    """The seed whose run has the lowest validation FDE (`validate` stage: iid, val split) for (variant, scene)."""
    scores = {}
    for path in val_dir.glob(f"{variant}-{scene}-s*-iid.json"):
        m = NAME.match(path.stem)
        if m and m.group(1) == variant and m.group(2) == scene:
            scores[int(m.group(3))] = json.loads(path.read_text())["fde"]
    if not scores:
        raise SystemExit(f"no validation results for {variant}-{scene} in {val_dir}")
    return min(scores, key=scores.get)


def choose(res: dict, scene: str) -> str:
    """The shippable variant with the lowest mean of (iid, paper) FDE over the scenes other than ``scene``."""
    def complete(v: str) -> bool:
        seeds = [set(res.get((v, s, p), {})) for s in SCENES for p in ("iid", "paper")]
        return bool(seeds[0]) and all(x == seeds[0] for x in seeds)

    def score(v: str) -> float:
        return float(np.mean([np.mean([f for o in SCENES if o != scene for _, f in res[(v, o, p)].values()])
                              for p in ("iid", "paper")]))

    candidates = [v for v in SHIPPABLE if complete(v)]
    if not candidates:
        raise SystemExit(f"no variant of {SHIPPABLE[:2]}... evaluated in every scene under both protocols")
    return min(candidates, key=score)


USAGE = ("usage: synthetic_pretraining_report.py EVAL_DIR | best-seed VAL_DIR VARIANT SCENE | "
         "choose EVAL_DIR SCENE")


def main(argv: list[str]) -> int:
    if argv in (["-h"], ["--help"]):
        print(f"{USAGE}\n\n{__doc__}")
        return 0
    if len(argv) == 4 and argv[0] == "best-seed":
        print(best_seed(Path(argv[1]), argv[2], argv[3]))
        return 0
    if len(argv) == 3 and argv[0] == "choose" and argv[2] in SCENES:
        print(choose(load(Path(argv[1])), argv[2]))
        return 0
    if len(argv) != 1 or not Path(argv[0]).is_dir():
        print(USAGE, file=sys.stderr)
        return 2
    res = load(Path(argv[0]))
    for protocol in ("iid", "paper"):
        print("\n".join(table(res, protocol)))
    for protocol in ("iid", "paper"):
        candidates = tuple(v for v in FINE_TUNED if all((v, s, protocol) in res for s in SCENES))
        if len(candidates) >= 2:
            print("\n".join(leave_one_scene_out(res, protocol, candidates)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
