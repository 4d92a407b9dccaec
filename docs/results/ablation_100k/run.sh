#!/usr/bin/env bash
# The ablation in its 100k regime (+exp=ablation_100k, 4 methods x 100 robots x GA
# seeds 0, 1, 2) into runs/ablation_100k/: docs/results/ablation/run.sh with that
# experiment and the paper's four arms; resumable the same way. SEEDS="1 2" limits it
# to some seeds, ARMS="E+L" to some arms.
#   docs/results/ablation_100k/run.sh                  # from the repository root
#   python -m analysis.report runs/ablation_100k --out docs/results/ablation_100k [--first 60]
EXP=ablation_100k SEEDS=${SEEDS:-0 1 2} ARMS=${ARMS:-E+L E+R R+L R+R} \
  exec "$(dirname "$0")/../ablation/run.sh"
