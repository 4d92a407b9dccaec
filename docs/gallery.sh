#!/usr/bin/env bash
# The gallery's clips (docs/gallery.md): each robot trained from scratch with +exp=train
# (seed 0, 150k env steps) in the task and arena it was made for, then its deterministic
# policy replayed by evo.replay into a short small clip.
#
#   MUJOCO_GL=egl bash docs/gallery.sh [OUT] [override ...]
#
# OUT (default docs/gallery) receives <label>.webm; the trainings go to runs/gallery/.
# Overrides are added to every training (a smaller budget for a quick look). A training
# already in runs/gallery/ is kept: the same command again only remakes the clips.
# GALLERY_ONLY=<label> makes that clip alone.
set -euo pipefail
out=${1:-docs/gallery}
shift || true
mkdir -p "$out"
H=docs/results/designer/head_to_head

clip () {  # label, robot file, then the task's and arena's overrides
  local label=$1 robot=$2
  shift 2
  [ -z "${GALLERY_ONLY:-}" ] || [ "$GALLERY_ONLY" = "$label" ] || return 0
  local run=runs/gallery/$label
  [ -f "$run/policy.pt" ] || python evo/main.py +exp=train robot="$robot" seed=0 record=off \
      "$@" "${extra[@]}" hydra.run.dir="$run"
  python -m evo.replay "$run" --episodes 4 --video "$out/$label.webm" \
      --size 320x240 --fps 10 --seconds 12
}

extra=("$@")
clip reach_clean_evolved $H/clean/robots/E+L+I_seed3.json env=clean
clip reach_clean_designed $H/clean/robots/twisted_four_wheeler.json env=clean
clip reach_cluttered_evolved $H/cluttered/robots/E+L_seed1.json env=cluttered
clip reach_cluttered_designed $H/cluttered/robots/twisted_four_wheeler.json env=cluttered
M=docs/results/tasks/matrix/bodies  # each task's chosen bodies (Tasks beyond reach)
clip locomotion_evolved $M/locomotion_evolved.json env/task=locomotion
clip locomotion_designed $M/locomotion_designed.json env/task=locomotion
clip push_evolved $M/push_evolved.json env/task=push
clip push_designed $M/locomotion_designed.json env/task=push
clip rough_evolved $M/rough_evolved.json env/task=rough
clip rough_designed $M/rough_designed.json env/task=rough
