#!/usr/bin/env bash
# Rerun the grip-to-force study (about 5 minutes on 2 CPU cores): the rods' presses, their contact model, its
# evaluation beside the shipped contact model, and the grip scene. Run from the repository root:
#   bash experiments/grip_to_force/run.sh [WORK_DIR]
# The model and the evaluation are written into this folder (the committed ones are replaced); the presses and
# the training run go to WORK_DIR (default runs/grip_to_force), the trials to WORK_DIR/trials.
set -euo pipefail
here=experiments/grip_to_force
work=${1:-runs/grip_to_force}
mkdir -p "$work"
tactile-manip simulate --config configs/dataset/contact_rods.toml --workers 2 --out "$work/contact_rods.npz" --force
tactile-manip train --config "$here/contact_rods.train.toml" --data "$work/contact_rods.npz" --out "$work/train" --force
tactile-manip export --checkpoint "$work/train/best.pt" --out "$here/contact_rods.onnx" --data "$work/contact_rods.npz" \
    --history "$work/train/history.json" --force
cp "$work/train/history.json" "$here/contact_rods.history.json"
tactile-manip evaluate --data "$work/contact_rods.npz" --model "rods=$here/contact_rods.onnx" \
    --model "shipped=models/contact_supermag.onnx" --out "$here/eval" --force
tactile-manip trials --config configs/scenes/grip_sim.toml --out "$work/trials"
