#!/usr/bin/env bash
# Quality at equal cost: +exp=paper_clean and +exp=paper_clean_early, GA seeds 0, 1, 2,
# one run at a time with the default local executor (one worker per core). Resumable:
# rerun it to continue every unfinished run.
#   docs/results/early_rejection/run.sh          # from the repository root
#   python -m analysis.equal_cost --without runs/paper_clean --with runs/paper_clean_early \
#       --out docs/results/early_rejection
set -u
cd "$(dirname "$0")/../../.."
py=${PYTHON:-.venv/bin/python}
mkdir -p runs
for seed in 0 1 2; do
  for exp in paper_clean_early paper_clean; do
    dir=runs/$exp/seed$seed
    if grep -qs '"complete": true' "$dir/summary.json"; then continue; fi
    if [ -f "$dir/state.json" ]; then
      args=("resume=$dir")
    else
      args=(+exp=$exp hydra.mode=RUN seed=$seed "hydra.run.dir=$dir")
    fi
    MUJOCO_GL=egl "$py" evo/main.py "${args[@]}" >> "runs/early_rejection.log" 2>&1 || exit
  done
done
