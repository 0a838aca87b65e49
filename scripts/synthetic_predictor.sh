#!/usr/bin/env bash
# Regenerate the crowdsim training data and retrain the packaged `gpgraph-stgcnn-synthetic` (GP-Graph+S on
# the STGCNN backbone with the pairwise group assigner) and `stgcnn-synthetic` (backbone alone) predictors, evaluate them on the held-out
# test split, and copy them into predictor/checkpoints/. THREADS torch threads (default 1); see RESULTS.md, section
# "Default synthetic predictor (gpgraph-stgcnn-synthetic)", for the numbers this produced.
#
#   scripts/synthetic_predictor.sh [data|train|evaluate|sweep|package|all]    (default: all)
#
# Everything goes under out/synthetic_predictor/ (ignored by git) except the packaged checkpoints.
set -euo pipefail
cd "$(dirname "$0")/.."

VENV=${VENV:-.venv}
ROOT=${ROOT:-out/synthetic_predictor}
DATA=$ROOT/data
RUNS=$ROOT/runs
EVAL=$ROOT/eval
THREADS=${THREADS:-1}
EPOCHS=${EPOCHS:-80}  # validation loss bottoms out by epoch ~30-50 on this much data (RESULTS.md); lr halves at 50
BCE=${BCE:-2.0}  # GP-Graph+S group-loss weight: 2.0 chosen over 1.0 on the validation split (RESULTS.md)
# group assigner: pairwise (predictor/pair_assigner.py; the shipped gpgraph-stgcnn-synthetic since 2026-11-25) or
# conv (GP-Graph's F_phi; `package` then writes gpgraph-stgcnn-synthetic-conv). RESULTS.md "Pairwise group assigner"
ASSIGNER=${ASSIGNER:-pairwise}
case $ASSIGNER in
    pairwise) PACKAGED=gpgraph-stgcnn-synthetic ;;
    conv) PACKAGED=gpgraph-stgcnn-synthetic-conv ;;
    *) echo "ASSIGNER must be pairwise or conv, got '$ASSIGNER'" >&2; exit 2 ;;
esac
export OMP_NUM_THREADS=$THREADS MKL_NUM_THREADS=$THREADS OPENBLAS_NUM_THREADS=$THREADS NUMBA_NUM_THREADS=1

stage=${1:-all}
SCALE=${SCALE:-}
MODE=${MODE:-}

data() {
    # The training preset realistic-v1 (crowdsim/presets.py: each recording's crowd size, geometry, speeds,
    # group sizes, spacing, radii and behaviour mix drawn from its seed): 36 recordings per scenario (corridor,
    # crossing, plaza, circle_crossing), seeds 1000-1035 -> split_of: 24 train, 6 val, 6 test per scenario.
    # Many short recordings (48 s at 0.4 s, after a 10 s warm-up) rather than few long ones: as many windows
    # as 12 x 120 s, three times the variety (12 x 120 s overfitted after ~30 epochs).
    rm -rf "$DATA"
    "$VENV/bin/crowdsim" dataset --preset realistic-v1 --seeds-per-scenario 36 --seed 1000 --duration 48 \
        --warmup 10 --workers 2 --out "$DATA"
}

train() {
    # The reference recipe (gpgraph train defaults: Adam lr 0.01, weight decay 1e-4, batch 128, clip 10,
    # lr halved at epochs 50 and 100, lowest validation loss kept) for EPOCHS epochs, seed 0, one thread.
    # GP-Graph+S: --bce-weight 1.0 adds the pairwise BCE loss on crowdsim's per-frame group labels.
    mkdir -p "$RUNS"
    local t0=$SECONDS
    "$VENV/bin/gpgraph" train --threads "$THREADS" --data "$DATA" --backbone stgcnn --bce-weight "$BCE" --epochs "$EPOCHS" \
        --assigner "$ASSIGNER" --seed 0 --quiet --out "$RUNS/gpgraph-stgcnn-synthetic"
    echo "gpgraph-stgcnn-synthetic: $((SECONDS - t0)) s" | tee "$RUNS/wall_time_gpgraph.txt"
    "$VENV/bin/gpgraph" train --threads "$THREADS" --data "$DATA" --backbone stgcnn --no-groups --epochs "$EPOCHS" \
        --seed 0 --quiet --out "$RUNS/stgcnn-synthetic"
    echo "training wall time: $((SECONDS - t0)) s" | tee "$RUNS/wall_time.txt"
}

evaluate() {
    mkdir -p "$EVAL"
    for model in gpgraph-stgcnn-synthetic stgcnn-synthetic; do
        for protocol in iid paper; do
            "$VENV/bin/gpgraph" evaluate --threads 1 --checkpoint "$RUNS/$model/best.pt" --data "$DATA" \
                --protocol "$protocol" --seed 0 --trials 10 --json "$EVAL/$model-$protocol.json"
        done
    done
    "$VENV/bin/python" scripts/eval_baselines.py --data "$DATA" --seed 0 --trials 10 \
        --json "$EVAL/baselines.json"
    # per test recording (scenario and crowd size): each file scored on its own, seed 0
    "$VENV/bin/python" scripts/eval_by_scenario.py --checkpoint constant-velocity --data "$DATA" --seed 0 \
        --trials 10 --json "$EVAL/by-file-constant-velocity.json"
    for model in gpgraph-stgcnn-synthetic stgcnn-synthetic; do
        for protocol in iid paper; do
            "$VENV/bin/python" scripts/eval_by_scenario.py --checkpoint "$RUNS/$model/best.pt" --data "$DATA" \
                --protocol "$protocol" --seed 0 --trials 10 --json "$EVAL/by-file-$model-$protocol.json"
        done
    done
}

sweep() {
    # GP-Graph+S groups by average linkage at SCALE x its learned threshold; the scale is chosen on the validation
    # split (docs/history/RESULTS-2026-11.md "Version 2.1" for the method), then `package` records it (SCALE=... package).
    mkdir -p "$EVAL"
    "$VENV/bin/python" scripts/sweep_group_threshold.py --checkpoint "$RUNS/gpgraph-stgcnn-synthetic/best.pt" \
        --data "$DATA" --split val --protocol iid --seed 0 --trials 3 --group-mode average \
        --scales 0.8 0.9 1.0 1.05 1.1 1.15 1.2 1.3 1.4 1.5 --json "$EVAL/threshold-sweep-val-average.json"
}

read_json_key() {  # FILE KEY: print one top-level value of a JSON file
    "$VENV/bin/python" -c 'import json, sys; print(json.load(open(sys.argv[1]))[sys.argv[2]])' "$1" "$2"
}

package() {
    # SCALE: the sweep's choice (read from its JSON) unless given; its grouping mode likewise
    local sweep_json="$EVAL/threshold-sweep-val-average.json"
    local scale mode
    scale=$SCALE
    mode=$MODE
    if [ -z "$scale" ]; then scale=$(read_json_key "$sweep_json" chosen); fi
    if [ -z "$mode" ]; then mode=$(read_json_key "$sweep_json" chosen_group_mode); fi
    "$VENV/bin/python" scripts/package_checkpoint.py "$RUNS/gpgraph-stgcnn-synthetic/best.pt" \
        "predictor/checkpoints/$PACKAGED.safetensors" --scene synthetic --data "$DATA" \
        --group-mode "$mode" --group-threshold-scale "$scale"
    "$VENV/bin/python" scripts/package_checkpoint.py "$RUNS/stgcnn-synthetic/best.pt" \
        "predictor/checkpoints/stgcnn-synthetic.safetensors" --scene synthetic --data "$DATA"
}

case $stage in
    data) data ;;
    train) train ;;
    evaluate) evaluate ;;
    sweep) sweep ;;
    package) package ;;
    all) data; train; evaluate; sweep; package ;;
    *) echo "usage: $0 [data|train|evaluate|sweep|package|all]" >&2; exit 2 ;;
esac
