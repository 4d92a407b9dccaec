#!/usr/bin/env bash
# The ablation (+exp=ablation, 4 methods x 100 robots x GA seeds 0-4, and the fifth arm
# E+L+I): every unfinished run at once, one process each (executor=serial), sharing the
# machine's cores, so that all seeds grow together and a report over each run's first N
# robots (--first N) can be made before the end. Resumable: rerun it to continue every
# unfinished run. SEEDS="1 2" limits it to some seeds; ARMS="E+L+I" to some arms (method
# names, default all five; an arm already running elsewhere must not be started twice:
# its run lock would refuse it); EXP=<name> runs another regime of the same sweep into
# runs/<name>/ (docs/results/ablation_100k/run.sh does, with the paper's four arms).
# ARENA=cluttered evolves in the cluttered arena instead, into runs/<name>_cluttered/;
# ROBOTS=N evaluates N robots per run instead of 100 (both only when a run starts: a
# resumed run keeps its config). JOBS=N runs at most N at once (default: all; each
# process holds about 0.6 GB). The evolved side of the designer comparison:
#   ARENA=cluttered ROBOTS=60 ARMS="E+L E+L+I" SEEDS="0 1 2" docs/results/ablation/run.sh
#   docs/results/ablation/run.sh                  # from the repository root
#   ARMS="E+L+I" docs/results/ablation/run.sh     # only the fifth arm
# GA seeds 5-12 of the paper's four arms at 60 robots per run (the power analysis's plan):
#   SEEDS="5 6 7 8 9 10 11 12" ARMS="E+L E+R R+L R+R" ROBOTS=60 JOBS=4 docs/results/ablation/run.sh
#   python -m analysis.report runs/ablation --out docs/results/ablation [--first 60]
set -u
cd "$(dirname "$0")/../../.."
py=${PYTHON:-.venv/bin/python}
exp=${EXP:-ablation}
arena=${ARENA:-clean}
case "$arena" in
  clean) root=runs/$exp; extra=() ;;
  cluttered) root=runs/${exp}_cluttered; extra=(env=cluttered) ;;
  *) echo "ARENA: expected clean or cluttered, got '$arena'" >&2; exit 2 ;;
esac
if [ -n "${ROBOTS:-}" ]; then extra+=(ga.robot_budget="$ROBOTS"); fi
jobs_at_once=${JOBS:-0}
case "$jobs_at_once" in
  ''|*[!0-9]*) echo "JOBS: expected a whole number of runs at once, got '$jobs_at_once'" >&2
               exit 2 ;;
esac
arms=" ${ARMS:-E+L E+R R+L R+R E+L+I} "
one() {
  local structure=$1 learner=$2 name=$3 seed=$4
  shift 4  # the rest: the arm's own overrides
  local dir=$root/${name}_seed$seed
  if grep -qs '"complete": true' "$dir/summary.json"; then return; fi
  if [ -f "$dir/state.json" ]; then
    args=("resume=$dir")
  else
    args=(+exp="$exp" hydra.mode=RUN ga.structure="$structure" learner="$learner"
          seed="$seed" executor=serial "hydra.run.dir=$dir" "${extra[@]}" "$@")
  fi
  MUJOCO_GL=egl "$py" evo/main.py "${args[@]}" >> "runs/${root#runs/}_${name}_seed$seed.log" 2>&1
}
# Each arm: structure, learner, method name, then its overrides. E+L+I is E+L whose
# offspring start from a parent's trained policy (ga.inheritance=parent). It keeps the
# whole budget (ga.schedule.inherited=1.0): in this regime a robot gets 32 arenas x 64
# steps x 25 batches = 51,200 env steps, 1,600 control steps per arena; half of it
# leaves each arena about 800 control steps, fewer than an episode's T_max of 1,000, so
# an episode that fails would never end, and the fitness (paper Eq. 8, the mean return
# of the completed episodes) would average the successes only (evo warns at start).
specs=("E ppo E+L" "E random E+R" "R ppo R+L" "R random R+R"
       "E ppo E+L+I ga.inheritance=parent ga.schedule.inherited=1.0")
for arm in $arms; do
  known=no
  for spec in "${specs[@]}"; do
    read -r -a words <<< "$spec"
    if [ "${words[2]}" = "$arm" ]; then known=yes; fi
  done
  if [ $known = no ]; then
    echo "ARMS: unknown arm '$arm'; expected some of: E+L E+R R+L R+R E+L+I" >&2
    exit 2
  fi
done
mkdir -p runs
for seed in ${SEEDS:-0 1 2 3 4}; do
  for spec in "${specs[@]}"; do
    read -r -a words <<< "$spec"
    case "$arms" in *" ${words[2]} "*) ;; *) continue ;; esac
    if [ "$jobs_at_once" -gt 0 ]; then  # wait for a free place, in seed order
      while [ "$(jobs -rp | wc -l)" -ge "$jobs_at_once" ]; do wait -n; done
    fi
    one "${words[@]:0:3}" "$seed" "${words[@]:3}" &
  done
done
wait
