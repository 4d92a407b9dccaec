#!/usr/bin/env bash
# The ablation (+exp=ablation, 4 methods x 100 robots x GA seeds 0, 1, 2) as four chains
# side by side, one per method and one core's worth each (executor=serial), each chain
# running its seeds in turn. Resumable: rerun it to continue every unfinished run.
#   docs/results/ablation/run.sh                  # from the repository root
#   python -m analysis.report runs/ablation --out docs/results/ablation
set -u
cd "$(dirname "$0")/../../.."
py=${PYTHON:-.venv/bin/python}
chain() {
  local structure=$1 learner=$2 name=$3
  for seed in 0 1 2; do
    dir=runs/ablation/${name}_seed$seed
    if grep -qs '"complete": true' "$dir/summary.json"; then continue; fi
    if [ -f "$dir/state.json" ]; then
      args=("resume=$dir")
    else
      args=(+exp=ablation hydra.mode=RUN ga.structure="$structure" learner="$learner"
            seed=$seed executor=serial "hydra.run.dir=$dir")
    fi
    MUJOCO_GL=egl "$py" evo/main.py "${args[@]}" >> "runs/ablation_${name}.log" 2>&1 || return
  done
}
mkdir -p runs
for spec in "E ppo E+L" "E random E+R" "R ppo R+L" "R random R+R"; do
  # shellcheck disable=SC2086
  chain $spec &
done
wait
