"""Markdown tables from ``gpgraph evaluate --json`` result files.

Usage: ``python -m predictor.report RESULTS_DIR`` where files are named ``<model>-<scene>-<protocol>.json``
(for example ``gpgraph-stgcnn-hotel-iid.json``). Prints one table per protocol: ADE/FDE per scene and the
5-scene average, plus COL and TCC averages, one row per model.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

SCENES = ("eth", "hotel", "univ", "zara1", "zara2")


def nan_to_none(v: Any) -> Any:
    """``v`` with every NaN float (nested in dicts) replaced by None, for strict JSON result files."""
    if isinstance(v, dict):
        return {k: nan_to_none(x) for k, x in v.items()}
    return None if isinstance(v, float) and v != v else v


def load_results(folder: str | Path) -> dict[tuple[str, str, str], dict]:
    """{(model, scene, protocol): result} from ``<model>-<scene>-<protocol>.json`` files."""
    out = {}
    for path in sorted(Path(folder).glob("*.json")):
        parts = path.stem.split("-")
        if len(parts) < 3 or parts[-2] not in SCENES:
            continue
        out[("-".join(parts[:-2]), parts[-2], parts[-1])] = json.loads(path.read_text())
    return out


def table(results: dict[tuple[str, str, str], dict], protocol: str) -> str:
    """One markdown table (ADE/FDE per scene, averages) for ``protocol``."""
    models = sorted({m for m, _, p in results if p == protocol})
    head = "| model | " + " | ".join(SCENES) + " | avg ADE/FDE | avg COL % | avg TCC | seed, trials |"
    lines = [head, "|---" * (len(SCENES) + 5) + "|"]
    for model in models:
        cells, sums, n = [], [0.0, 0.0, 0.0, 0.0], 0
        meta = ""
        for scene in SCENES:
            r = results.get((model, scene, protocol))
            if r is None:
                cells.append("–")
                continue
            cells.append(f"{r['ade']:.2f}/{r['fde']:.2f}")
            sums = [s + r[k] for s, k in zip(sums, ("ade", "fde", "col", "tcc"), strict=True)]
            n += 1
            meta = f"{r['seed']}, {r['trials']}"
        avg = f"{sums[0] / n:.3f}/{sums[1] / n:.3f}" if n == len(SCENES) else "–"
        col = f"{sums[2] / n:.2f}" if n == len(SCENES) else "–"
        tcc = f"{sums[3] / n:.3f}" if n == len(SCENES) else "–"
        lines.append(f"| {model} | " + " | ".join(cells) + f" | {avg} | {col} | {tcc} | {meta} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print(__doc__, file=sys.stderr)
        return 2
    results = load_results(args[0])
    for protocol in sorted({p for _, _, p in results}):
        print(f"\nprotocol: {protocol}\n")
        print(table(results, protocol))
    return 0


if __name__ == "__main__":
    sys.exit(main())
