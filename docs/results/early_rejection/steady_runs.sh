#!/usr/bin/env bash
# The steady regime in runs: +exp=ablation_early (the rule) against +exp=ablation (no
# rule), for E+L and E+L+I, GA seeds 0-4, 60 robots per run, each run serial
# (executor=serial, so that a pair of runs of one seed is the same run until the rule
# first stops an offspring full training would have accepted). Per seed: the two runs
# with the rule at once, then the two without. Resumable: rerun it to continue every
# unfinished run. The runs land in runs/ablation_early/ and runs/ablation/ (a run
# already there is resumed with its own config, so start from a runs/ without them).
#   bash docs/results/early_rejection/steady_runs.sh     # about 13 minutes per pair
#   SEEDS="3 4" bash docs/results/early_rejection/steady_runs.sh
set -u
cd "$(dirname "$0")/../../.."
for seed in ${SEEDS:-0 1 2 3 4}; do
  EXP=ablation_early ARMS="E+L E+L+I" SEEDS=$seed ROBOTS=60 docs/results/ablation/run.sh
  EXP=ablation ARMS="E+L+I E+L" SEEDS=$seed ROBOTS=60 docs/results/ablation/run.sh
done
