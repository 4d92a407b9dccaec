#!/usr/bin/env bash
# Early rejection in +exp=ablation's regime, replayed offline on the ablation's committed
# runs (first 60 robots each): the rate and value predictors calibrated on GA seeds 0-6
# (E+L) and 0-2 (E+L+I) at checkpoints 0.4, 0.5 and 0.6 of the budget, then the rate
# predictor read on the held-out seeds 7-12 (E+L) and 3-4 (E+L+I).
#   bash docs/results/early_rejection/steady_rate.sh [OUT]   # default: steady_rate/ here
set -euo pipefail
cd "$(dirname "$0")/../../.."
py=${PYTHON:-.venv/bin/python}
R=docs/results/ablation/runs
out=${1:-docs/results/early_rejection/steady_rate}
mkdir -p "$out"
replay () { "$py" -W ignore bench/early_rejection.py "$@" >/dev/null; }
for cp in 0.4 0.5 0.6; do
  replay $R/E+L_seed{0..6} --first 60 --checkpoints $cp --margins 0.3 0.4 0.5 0.6 \
      --predictors rate value --out "$out/calib_E+L_$cp.md"
  replay $R/E+L+I_seed{0..2} --first 60 --checkpoints $cp --margins 0.3 0.4 0.5 0.6 \
      --predictors rate value --out "$out/calib_E+L+I_$cp.md"
done
for cp in 0.4 0.5; do
  replay $R/E+L_seed{7..12} --first 60 --checkpoints $cp --margins 0.4 0.5 0.6 \
      --predictors rate --out "$out/heldout_E+L_$cp.md"
  replay $R/E+L+I_seed{3..4} --first 60 --checkpoints $cp --margins 0.4 0.5 0.6 \
      --predictors rate --out "$out/heldout_E+L+I_$cp.md"
done
echo "$out"
