#!/usr/bin/env bash
# The ablation (+exp=ablation, 4 methods x 100 robots x GA seeds 0-4): every
# unfinished run at once, one process each (executor=serial), sharing the machine's
# cores, so that all seeds grow together and a report over each run's first N robots
# (--first N) can be made before the end. Resumable: rerun it to continue every
# unfinished run. SEEDS="1 2" limits it to some seeds; EXP=<name> runs another regime of
# the same sweep into runs/<name>/ (docs/results/ablation_100k/run.sh does).
#   docs/results/ablation/run.sh                  # from the repository root
#   python -m analysis.report runs/ablation --out docs/results/ablation [--first 60]
set -u
cd "$(dirname "$0")/../../.."
py=${PYTHON:-.venv/bin/python}
exp=${EXP:-ablation}
one() {
  local structure=$1 learner=$2 name=$3 seed=$4
  local dir=runs/$exp/${name}_seed$seed
  if grep -qs '"complete": true' "$dir/summary.json"; then return; fi
  if [ -f "$dir/state.json" ]; then
    args=("resume=$dir")
  else
    args=(+exp="$exp" hydra.mode=RUN ga.structure="$structure" learner="$learner"
          seed="$seed" executor=serial "hydra.run.dir=$dir")
  fi
  MUJOCO_GL=egl "$py" evo/main.py "${args[@]}" >> "runs/${exp}_${name}_seed$seed.log" 2>&1
}
mkdir -p runs
for seed in ${SEEDS:-0 1 2 3 4}; do
  for spec in "E ppo E+L" "E random E+R" "R ppo R+L" "R random R+R"; do
    # shellcheck disable=SC2086
    one $spec "$seed" &
  done
done
wait
