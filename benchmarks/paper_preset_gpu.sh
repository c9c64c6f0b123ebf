#!/usr/bin/env bash
# The paper preset on a GPU, for Table I's "within 0.5 dB of the paper preset at equal epochs" check:
# regenerate the default dataset (checks its fingerprint), train the paper preset for as many epochs as the
# shipped compact model (32), export it, evaluate it beside the shipped model on the unseen test objects,
# and time both presets on the GPU. Needs torch with CUDA, onnx and onnxruntime.
#   bash benchmarks/paper_preset_gpu.sh OUTDIR [EPOCHS]
set -euo pipefail
out=${1:?usage: paper_preset_gpu.sh OUTDIR [EPOCHS]}
epochs=${2:-32}
mkdir -p "$out"
export PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH} PYTHONUNBUFFERED=1
tm() { python3 -m tactile_manip "$@"; }
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
python3 -c "import torch, onnxruntime; print('torch', torch.__version__, 'onnxruntime', onnxruntime.__version__)"
[ -f data/supermag.npz ] || tm simulate --out data/supermag.npz
python3 -c "from tactile_manip.data import load_dataset as l; print('data fingerprint', l('data/supermag.npz').fingerprint())"
python3 -m pytest -q -p no:cacheprovider tests/learning/test_train.py -k "gpu or device"
tm train --config configs/train/paper.toml --data data/supermag.npz --out runs/paper_gpu \
    --epochs "$epochs" --max-minutes 0 --device cuda 2>&1 | tr '\r' '\n' | sed '/^\s*$/d'
cp runs/paper_gpu/history.json runs/paper_gpu/loss.png "$out"/
tm export --checkpoint runs/paper_gpu/best.pt --out runs/paper_gpu/model.onnx --data data/supermag.npz
tm evaluate --data data/supermag.npz --threads 4 --out "$out/eval" \
    --model "SuperMag paper preset ($epochs ep, GPU)=runs/paper_gpu/model.onnx" \
    --model "SuperMag compact, shipped (32 ep)=experiments/model_variants/supermag_compact.onnx"
python3 -m benchmarks.bench_gpu --out "$out/gpu.json"
echo done
