#!/usr/bin/env bash
# The RMR ablations (docs/rmr-benchmarks.md, "Ablations") at equal budgets: every run trains
# the same number of epochs from the same seed on the same pairs, with the paper's input (`--paper`), loss and
# learning rate. Table 1: the refiner cell (LSTM, GRU, BLSTM, BGRU); Table 2: T_begin (3, 5,
# 10); Figure 9: without the root trajectory loss. Then the stitching benchmark over all of
# them and the root-drift plot of Figure 9.
#
#   scripts/rmr_ablations.sh [EPOCHS] [OUT]        # defaults: 20 epochs, runs/rmr-ablations
#
# DATA (default ../shared/data/bandai2), EXTRA (more `zoo train rmr` flags for every run,
# e.g. EXTRA='--seam-weight 4 --threads 1') and ZOO (a zoo binary to use instead of building
# target/release/zoo, e.g. a copy that a rebuild cannot replace mid-run; the Figure 9 example
# is then taken from TRAJECTORY, default target/release/examples/trajectory_ablation) can be
# set in the environment. An interrupted script resumes:
# finished runs are kept, an unfinished one continues from its last checkpoint.
set -euo pipefail
cd "$(dirname "$0")/.."
EPOCHS=${1:-20}
OUT=${2:-runs/rmr-ablations}
DATA=${DATA:-../shared/data/bandai2}
GLOB='*_youthful_*'
EXTRA=${EXTRA:-}
if [ ! -d "$DATA" ]; then
  echo "error: $DATA not found: the ablations train on bandai2 (set DATA to its folder)" >&2
  exit 1
fi
if [ -z "${ZOO:-}" ]; then
  cargo build --release --bin zoo
  cargo build --release -p zoo-rmr --example trajectory_ablation
  ZOO=target/release/zoo
fi
TRAJECTORY=${TRAJECTORY:-target/release/examples/trajectory_ablation}
mkdir -p "$OUT"

# train NAME FLAGS...: trains (or resumes) one run unless it has finished.
train() {
  local name=$1
  shift
  local dir="$OUT/$name"
  if [ -f "$dir/summary.json" ]; then
    echo "== $name: done already ($dir)"
    return
  fi
  echo "== $name: $EPOCHS epochs $* $EXTRA"
  if [ -f "$dir/train_state.json" ] || [ -d "$dir/last" ]; then
    # shellcheck disable=SC2086
    $ZOO train rmr --data "$DATA" --valid-glob "$GLOB" --epochs "$EPOCHS" --resume "$dir"
  else
    # A folder without a checkpoint holds at most the pair cache: nothing to keep.
    local again=()
    [ -d "$dir" ] && again=(--overwrite)
    # shellcheck disable=SC2086
    $ZOO train rmr --data "$DATA" --valid-glob "$GLOB" --epochs "$EPOCHS" --out "$dir" --paper "${again[@]}" "$@" $EXTRA
  fi
}

train bgru-tb5 --cell bgru --t-begin 5
train lstm --cell lstm --t-begin 5
train gru --cell gru --t-begin 5
train blstm --cell blstm --t-begin 5
train bgru-tb3 --cell bgru --t-begin 3
train bgru-tb10 --cell bgru --t-begin 10
train bgru-no-trajectory --cell bgru --t-begin 5 --no-trajectory-loss

methods=concat,inertialize
for r in bgru-tb5 lstm gru blstm bgru-tb3 bgru-tb10 bgru-no-trajectory; do
  methods="$methods,rmr:$OUT/$r,rmr+ik:$OUT/$r"
done
$ZOO bench stitch --data "$DATA" --valid-glob "$GLOB" --methods "$methods" --json "$OUT/stitch.json" | tee "$OUT/stitch.txt"
$TRAJECTORY --data "$DATA" --valid-glob "$GLOB" \
  --model "$OUT/bgru-tb5" --model "$OUT/bgru-no-trajectory" --png "$OUT/trajectory.png" | tee "$OUT/trajectory.txt"
