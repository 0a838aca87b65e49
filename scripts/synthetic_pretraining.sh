#!/bin/bash
# What crowdsim pretraining buys on real data (issue 12, item 3): on every ETH/UCY leave-one-scene-out split,
# GP-Graph-STGCNN trained three ways, with the same budget on the split's real training data:
#   real      random initial weights, EPOCHS epochs on the split's train set;
#   pretrain  initial weights from INIT (default gpgraph-stgcnn-synthetic-conv: GP-Graph+S with GP-Graph's own
#             group assigner, trained on crowdsim's realistic-v1 preset only, RESULTS.md "Default synthetic
#             predictor"; the fine-tuned runs use that assigner too), then the same EPOCHS epochs;
#   pretrainlow  (only with VARIANTS="pretrainlow") the same fine-tuning at lr 0.001 instead of 0.01;
#   pretrainvlow (only with VARIANTS="pretrainvlow") at lr 0.0001;
#   zeroshot  INIT itself, never trained on real people, grouping as the fine-tuned runs
#             (connected components); zeroshotavg: the same with its packaged average-linkage grouping;
#   wise<100a>  (stage `interpolate`) the weights (1 - a) * INIT + a * each finished pretrainlow run, a in ALPHAS
#             (WiSE-FT, predictor/interpolate.py; `gpgraph interpolate`); no training.
# Every run keeps the checkpoint with the lowest validation loss; evaluation is the RESULTS.md protocol (test
# split, seed 0, 10 trials, iid and paper). One thread per process, JOBS processes at a time.
#   bash scripts/synthetic_pretraining.sh train SEED [SEED ...]    # trains the missing runs (VARIANTS=...)
#   bash scripts/synthetic_pretraining.sh interpolate               # wise<100a> runs from the pretrainlow ones
#   bash scripts/synthetic_pretraining.sh evaluate                  # evaluates every finished run + zero-shot
#   bash scripts/synthetic_pretraining.sh validate                  # the same runs on the validation splits (VARIANTS=...)
#   bash scripts/synthetic_pretraining.sh report                    # the per-scene table (python)
#   bash scripts/synthetic_pretraining.sh package                   # ships gpgraph-stgcnn-<scene>-pretrained
# The 2026-11-23 runs in RESULTS.md started from the gpgraph-stgcnn-synthetic of commit 438cd77 (the conv assigner,
# trained on crowdsim before the group catch-up term; `git show 438cd77:predictor/checkpoints/gpgraph-stgcnn-synthetic.safetensors`
# gets it, INIT=PATH uses it); those of 2026-11-26/27 and the packaged -pretrained version 2 from the default INIT,
# gpgraph-stgcnn-synthetic-conv (OUT=out/s10/ft EPOCHS=40, then interpolate, evaluate, VARIANTS="wise50 wise75" validate,
# package).
# Outputs under OUT (default out/synthetic_pretraining): runs/<variant>-<scene>-s<seed>/, eval/*.json.
set -euo pipefail
stage=$1; shift
out=${OUT:-out/synthetic_pretraining}
py=${PY:-.venv/bin/python}
data=${DATA:-$("$py" -c "from predictor.ethucy import DEFAULT_DATA_DIR; print(DEFAULT_DATA_DIR)")}  # ETH_UCY_DIR
INIT=${INIT:-gpgraph-stgcnn-synthetic-conv}
export INIT
epochs=${EPOCHS:-40}
jobs=${JOBS:-2}
scenes=${SCENES:-"eth hotel univ zara1 zara2"}
export OMP_NUM_THREADS=1
mkdir -p "$out/runs" "$out/eval"

train_one() {  # variant scene seed
  local run="$out/runs/$1-$2-s$3" init=()
  [ -f "$run/done" ] && return 0
  [ "$1" = pretrain ] && init=(--init "$INIT")
  [ "$1" = pretrainlow ] && init=(--init "$INIT" --lr 0.001)
  [ "$1" = pretrainvlow ] && init=(--init "$INIT" --lr 0.0001)
  rm -rf "$run"
  "$py" -m predictor.cli train --threads 1 --backbone stgcnn --data "$data/$2" --out "$run" --epochs "$epochs" \
    --seed "$3" --eval-every 0 --quiet "${init[@]}" > "$run.log" 2>&1
  touch "$run/done"
  echo "trained $run"
}

eval_one() {  # checkpoint scene name protocol [extra evaluate flags]
  local json="$out/eval/$3-$4.json"
  [ -f "$json" ] && return 0
  "$py" -m predictor.cli evaluate --threads 1 --checkpoint "$1" --data "$data/$2" --protocol "$4" --seed 0 \
    --trials 10 --quiet --json "$json" "${@:5}" > /dev/null
  echo "wrote $json"
}
export -f train_one eval_one
export out data py epochs

case $stage in
  train)
    for seed in "$@"; do for scene in $scenes; do for variant in ${VARIANTS:-real pretrain}; do
      echo "$variant $scene $seed"
    done; done; done | xargs -P "$jobs" -L 1 bash -c 'train_one "$0" "$1" "$2"'
    ;;
  interpolate)  # WiSE-FT between INIT and every finished pretrainlow run; ALPHAS in (0, 1), default 0.25 0.5 0.75
    for run in "$out"/runs/pretrainlow-*-s*/; do
      [ -f "$run/done" ] || continue
      for a in ${ALPHAS:-0.25 0.5 0.75}; do
        name=$(basename "$run"); pct=$("$py" -c "print(round(100 * float('$a')))")
        dest="$out/runs/wise$pct-${name#pretrainlow-}"
        [ -f "$dest/done" ] && continue
        mkdir -p "$dest"
        "$py" -m predictor.cli interpolate --start "$INIT" --end "$run/best.pt" --alpha "$a" --out "$dest/best.pt" \
          > /dev/null
        touch "$dest/done"
        echo "interpolated $dest"
      done
    done
    ;;
  evaluate)
    {
      for scene in $scenes; do for protocol in iid paper; do
        # zero-shot with the grouping the fine-tuned runs use (connected components at the learned threshold);
        # the packaged default (average linkage x 1.15) as its own row
        echo "$INIT $scene zeroshot-$scene $protocol --group-mode exact --group-threshold-scale 1"
        echo "$INIT $scene zeroshotavg-$scene $protocol"
        for run in "$out"/runs/*-"$scene"-s*/; do
          [ -f "$run/done" ] || continue
          echo "$run/best.pt $scene $(basename "$run") $protocol"
        done
      done; done
    } | xargs -P "$jobs" -L 1 bash -c 'eval_one "$0" "$@"'
    ;;
  validate)  # best-of-20 ADE/FDE on each split's validation set (iid, 3 trials): a selection check without test
    mkdir -p "$out/val"
    for run in "$out"/runs/*-s*/; do
      [ -f "$run/done" ] || continue
      name=$(basename "$run"); scene=${name#*-}; scene=${scene%-s*}
      [ -n "${VARIANTS:-}" ] && [[ " $VARIANTS " != *" ${name%%-*} "* ]] && continue  # only these variants
      echo "$run $scene $name"
    done | xargs -P "$jobs" -L 1 bash -c 'f="$out/val/$2-iid.json"; [ -f "$f" ] || "$py" -m predictor.cli evaluate \
      --threads 1 --checkpoint "$0/best.pt" --data "$data/$1" --split val --protocol iid --seed 0 --trials 3 --quiet \
      --json "$f" > /dev/null'
    ;;
  report)
    "$py" scripts/synthetic_pretraining_report.py "$out/eval"
    ;;
  package)  # per scene the variant chosen leave-one-scene-out in `report` (mean of the iid and paper FDE on the
            # other four scenes), the seed with the best validation FDE (`validate`)
    for scene in $scenes; do
      variant=$("$py" scripts/synthetic_pretraining_report.py choose "$out/eval" "$scene")
      seed=$("$py" scripts/synthetic_pretraining_report.py best-seed "$out/val" "$variant" "$scene")
      "$py" scripts/package_checkpoint.py "$out/runs/$variant-$scene-s$seed/best.pt" \
        "predictor/checkpoints/gpgraph-stgcnn-$scene-pretrained.safetensors" --scene "$scene" --data "$data/$scene" \
        --note "crowdsim-pretrained ($INIT), fine-tuned $epochs epochs at lr 0.001, variant $variant (wise<100a>: \
weights (1 - a) * $INIT + a * fine-tuned) chosen leave-one-scene-out on the other scenes' test FDE, seed $seed of 0-2 \
by validation FDE; RESULTS.md 'What crowdsim pretraining buys'"
    done
    ;;
  *)
    echo "usage: $0 train SEED [SEED ...] | interpolate | evaluate | validate | report | package" >&2; exit 2
    ;;
esac
