#!/bin/bash
# One lever at a time back to the learner defaults, from the noise sweep's best (trial 2),
# on the sweep's 16 robots x 2 seeds x 50k (its trial protocol).
cd "$(dirname "$0")/../../../.."
export MUJOCO_GL=egl
PY=${PYTHON:-.venv/bin/python}
BEST="learner.lmbda=0.8 learner.minibatch_size=1024 learner.entropy_coeff=0 learner.init_log_std=-1 learner.reward_scaling=true physics_step=dt6p25ms_x8"
for lever in learner.lmbda=0.95 learner.minibatch_size=512 learner.entropy_coeff=0.005 learner.init_log_std=-0.5 learner.reward_scaling=false; do
  key=${lever%%=*}
  name=$(echo ${lever#learner.} | tr '=' '_')
  others=$(for o in $BEST; do [ "${o%%=*}" != "$key" ] && echo -n "$o "; done)
  $PY evo/main.py +exp=retrain record=off seed=0 noise_ceiling.random=16 noise_ceiling.seeds=2 \
    noise_ceiling.budget=50000 noise_ceiling.baseline=false $others $lever \
    hydra.run.dir=runs/levers/$name >> runs/levers.log 2>&1
done
