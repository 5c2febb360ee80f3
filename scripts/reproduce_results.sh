#!/usr/bin/env bash
# Regenerate every committed result under docs/results/ from seeds, with the project's own
# commands: dataset generation, split, training, experiments. Each step is resumable: rerun
# the script after an interruption and finished work is kept (generate, train --resume and
# experiment run all skip what is done).
#
#   scripts/reproduce_results.sh            # everything, default sizes (~2 h on 2 CPU cores)
#   DATA=/tmp/d RUNS=/tmp/r scripts/reproduce_results.sh
#
# Environment (defaults in brackets): DATA [/work/data] dataset root, RUNS [$DATA/runs] model
# runs, OUT [docs/results] experiment folders, WORKERS [2], SEED [0], N_RDV [3000] rendezvous
# instances, N_ROB [1200] robust-rendezvous instances, EPOCHS [preset's] epochs of the
# rendezvous models, ROBUST_EPOCHS [12] of the robust ones, RAY [unset] Ray address.
set -euo pipefail

DATA=${DATA:-/work/data}
RUNS=${RUNS:-$DATA/runs}
OUT=${OUT:-docs/results}
WORKERS=${WORKERS:-2}
SEED=${SEED:-0}
N_RDV=${N_RDV:-3000}
N_ROB=${N_ROB:-1200}
RDV=$DATA/rdv$N_RDV
ROB=$DATA/rob$N_ROB
EPOCHS_FLAG=${EPOCHS:+--epochs $EPOCHS}
RAY_FLAG=${RAY:+--ray $RAY}

run() { echo "+ $*" >&2; "$@"; }

# 1. data: ART paper Table 1 ranges, Problem 2 and Problem 3 twins, grouped 80/10/10 split
if [ ! -f "$RDV/splits.h5" ]; then
  run scpformer generate rendezvous --n "$N_RDV" --seed "$SEED" --out "$RDV" --workers "$WORKERS"
  run scpformer dataset split "$RDV" --fractions 0.8 0.1 0.1 --seed "$SEED"
fi

# 2. models: ART, GRU and LSTM on the same sequences (small presets: two CPU cores)
for kind in art gru lstm; do
  if [ -f "$RUNS/$kind-small/checkpoint.pt" ]; then resume=--resume; else resume=; fi
  # shellcheck disable=SC2086
  run scpformer train "$kind" --data "$RDV" --out "$RUNS/$kind-small" --preset small \
    --frame rtn --seed "$SEED" $EPOCHS_FLAG $resume
done

# 3. experiments (ART paper): each writes results.csv, PNG figures and report.md
# shellcheck disable=SC2086
common=(--data "$RDV" --workers "$WORKERS" --seed "$SEED" $RAY_FLAG)
run scpformer experiment run art-warmstart --model "$RUNS/art-small" "${common[@]}" \
  --out "$OUT/art-warmstart"
run scpformer experiment run art-forecast-scp --model "$RUNS/art-small" \
  --model "$RUNS/gru-small" --model "$RUNS/lstm-small" "${common[@]}" \
  --out "$OUT/art-forecast-scp"
run scpformer experiment run art-forecast-tpbvp --model "$RUNS/art-small" \
  --model "$RUNS/gru-small" --model "$RUNS/lstm-small" "${common[@]}" \
  --out "$OUT/art-forecast-tpbvp"
run scpformer experiment run art-conditioning --model "$RUNS/art-small" "${common[@]}" \
  --out "$OUT/art-conditioning"

# 4. robust ART paper: chance-constrained dataset (three-stage procedure), ART on RTN and on
#    ROE states, SCvx* warm-started by CVX and ART in both passive-safety modes
if [ ! -f "$ROB/splits.h5" ]; then
  run scpformer generate robust-rendezvous --n "$N_ROB" --seed "$SEED" --out "$ROB" \
    --workers "$WORKERS"
  run scpformer dataset split "$ROB" --fractions 0.8 0.1 0.1 --seed "$SEED"
fi
# the RTN model as the lead trained it (12 epochs), and its ROE twin
if [ -f "$RUNS/art-robust-small/checkpoint.pt" ]; then resume=--resume; else resume=; fi
run scpformer train art --data "$ROB" --out "$RUNS/art-robust-small" --preset small \
  --frame rtn --seed "$SEED" --epochs "${ROBUST_EPOCHS:-12}" $resume
if [ -f "$RUNS/art-robust-roe-small/checkpoint.pt" ]; then resume=--resume; else resume=; fi
run scpformer train art --data "$ROB" --out "$RUNS/art-robust-roe-small" --preset small \
  --frame roe --seed "$SEED" --epochs "${ROBUST_EPOCHS:-12}" $resume
# shellcheck disable=SC2086
run scpformer experiment run robust-warmstart --model "$RUNS/art-robust-small" \
  --model "$RUNS/art-robust-roe-small" --data "$ROB" --workers "$WORKERS" --seed "$SEED" \
  $RAY_FLAG --out "$OUT/robust-warmstart"
# the instance with the largest ART gain, and the post hoc check (RTN model, as the paper)
for name in robust-trajectory robust-posthoc; do
  # shellcheck disable=SC2086
  run scpformer experiment run "$name" --model "$RUNS/art-robust-small" --data "$ROB" \
    --workers "$WORKERS" --seed "$SEED" $RAY_FLAG --out "$OUT/$name"
done
# one page: the paper's numbers beside ours for every experiment above
run scpformer report --results "$OUT" --out "$(dirname "$OUT")/RESULTS.md"
