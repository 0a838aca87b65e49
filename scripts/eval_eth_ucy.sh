#!/bin/bash
# Evaluate packaged checkpoints on the ETH/UCY leave-one-scene-out test sets under both protocols.
#   bash scripts/eval_eth_ucy.sh OUT_DIR MODEL [MODEL ...]     (MODEL: e.g. gpgraph-sgcn, stgcnn)
# Writes OUT_DIR/<model>-<scene>-<protocol>.json (existing files are kept) and prints the tables of
# `python -m predictor.report OUT_DIR`. Seed 0, 10 trials, one thread per evaluation. See RESULTS.md.
set -euo pipefail
out=$1; shift
py=${PY:-.venv/bin/python}
data=${DATA:-$("$py" -c "from predictor.ethucy import DEFAULT_DATA_DIR; print(DEFAULT_DATA_DIR)")}  # ETH_UCY_DIR
mkdir -p "$out"
for model in "$@"; do
  for scene in eth hotel univ zara1 zara2; do
    for protocol in iid paper; do
      json="$out/$model-$scene-$protocol.json"
      [ -f "$json" ] && continue
      if [ ! -f "predictor/checkpoints/$model-$scene.safetensors" ]; then
        echo "skip $model-$scene: not packaged"; continue
      fi
      "$py" -m predictor.cli evaluate --threads 1 --checkpoint "$model-$scene" --data "$data/$scene" \
        --protocol "$protocol" --seed 0 --trials 10 --json "$json" > /dev/null
      echo "wrote $json"
    done
  done
done
"$py" -m predictor.report "$out"
