#!/usr/bin/env bash
# Regenerate the crowdsim training data and retrain the packaged `gpgraph-stgcnn-synthetic` (GP-Graph+S on
# the STGCNN backbone) and `stgcnn-synthetic` (backbone alone) predictors, evaluate them on the held-out
# test split, and copy them into predictor/checkpoints/. Single-threaded; see RESULTS.md, section
# "Default synthetic predictor (gpgraph-stgcnn-synthetic)", for the numbers this produced.
#
#   scripts/synthetic_predictor.sh [data|train|evaluate|package|all]    (default: all)
#
# Everything goes under out/synthetic_predictor/ (ignored by git) except the packaged checkpoints.
set -euo pipefail
cd "$(dirname "$0")/.."

VENV=${VENV:-.venv}
ROOT=${ROOT:-out/synthetic_predictor}
DATA=$ROOT/data
RUNS=$ROOT/runs
EVAL=$ROOT/eval
EPOCHS=${EPOCHS:-300}
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 NUMBA_NUM_THREADS=1

stage=${1:-all}

data() {
    # Six recordings per (scenario, crowd size) -> seeds s..s+3 train, s+4 val, s+5 test; three for the
    # variety scenarios -> s train, s+1 val, s+2 test (crowdsim.generate.split_of). Seed bases are 1000
    # apart, so no seed is shared between splits or between configurations. 120 s recorded at 0.4 s after
    # a 4 s warm-up; group sizes zero-truncated Poisson (lambda 1.1), no leave/merge events.
    rm -rf "$DATA"
    local common=(--duration 120 --warmup 4 --out "$DATA")
    "$VENV/bin/crowdsim" dataset --scenarios plaza --pedestrians 20 --seeds-per-scenario 6 --seed 1000 "${common[@]}"
    "$VENV/bin/crowdsim" dataset --scenarios plaza --pedestrians 30 --seeds-per-scenario 6 --seed 2000 "${common[@]}"
    "$VENV/bin/crowdsim" dataset --scenarios plaza --pedestrians 40 --seeds-per-scenario 6 --seed 3000 "${common[@]}"
    "$VENV/bin/crowdsim" dataset --scenarios circle_crossing --pedestrians 20 --seeds-per-scenario 6 --seed 4000 \
        "${common[@]}"
    "$VENV/bin/crowdsim" dataset --scenarios crossing,corridor --pedestrians 30 --seeds-per-scenario 3 --seed 5000 \
        "${common[@]}"
}

train() {
    # The reference recipe (gpgraph train defaults: Adam lr 0.01, weight decay 1e-4, batch 128, clip 10,
    # lr halved at epochs 50 and 100, 300 epochs, lowest validation loss kept), seed 0, one thread.
    # GP-Graph+S: --bce-weight 1.0 adds the pairwise BCE loss on crowdsim's per-frame group labels.
    mkdir -p "$RUNS"
    local t0=$SECONDS
    "$VENV/bin/gpgraph" train --threads 1 --data "$DATA" --backbone stgcnn --bce-weight 1.0 --epochs "$EPOCHS" \
        --seed 0 --quiet --out "$RUNS/gpgraph-stgcnn-synthetic"
    echo "gpgraph-stgcnn-synthetic: $((SECONDS - t0)) s" | tee "$RUNS/wall_time_gpgraph.txt"
    "$VENV/bin/gpgraph" train --threads 1 --data "$DATA" --backbone stgcnn --no-groups --epochs "$EPOCHS" \
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

package() {
    for model in gpgraph-stgcnn-synthetic stgcnn-synthetic; do
        "$VENV/bin/python" scripts/package_checkpoint.py "$RUNS/$model/best.pt" \
            "predictor/checkpoints/$model.safetensors" --scene synthetic --data "$DATA"
    done
}

case $stage in
    data) data ;;
    train) train ;;
    evaluate) evaluate ;;
    package) package ;;
    all) data; train; evaluate; package ;;
    *) echo "usage: $0 [data|train|evaluate|package|all]" >&2; exit 2 ;;
esac
