#!/usr/bin/env bash
# Rerun the paper's Table I with its ablation rows (hours on 2 CPU cores; each 8-epoch run takes the longest):
#   bash experiments/table1_ablation/run.sh [WORK_DIR]
# The dataset, runs and models go to WORK_DIR (default runs/table1_ablation); the table to
# experiments/table1_ablation/results/ (the committed one is replaced).
set -euo pipefail
here=experiments/table1_ablation
work=${1:-runs/table1_ablation}
mkdir -p "$work"
data="$work/supermag.npz"
[ -f "$data" ] || tactile-manip simulate --config configs/dataset/supermag.toml --out "$data"
models=()
for name in full z_axis allen_key ak_r; do
  tactile-manip train --config "$here/table1_$name.toml" --data "$data" --out "$work/$name"
  tactile-manip export --checkpoint "$work/$name/best.pt" --out "$work/$name/model.onnx" --data "$data" --force
  models+=(--model "SuperMag ($name, 8 ep)=$work/$name/model.onnx")
done
tactile-manip train --config configs/train/paper.toml --data "$data" --out "$work/paper"
tactile-manip export --checkpoint "$work/paper/best.pt" --out "$work/paper/model.onnx" --data "$data" --force
tactile-manip evaluate --data "$data" --baseline-objects allen_key,letter_r "${models[@]}" \
    --model "SuperMag paper preset=$work/paper/model.onnx" --out "$here/results" --force
