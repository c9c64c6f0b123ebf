"""DistributedDataParallel with two gloo processes equals one process on the same global batch."""

import os
import subprocess
import sys

import pytest
from checks import TORCH_MISSING

pytest.importorskip("torch", reason=TORCH_MISSING)
import torch

from tactile_manip.learning.cvae.export import load_checkpoint

SCRIPT = """
import sys
from tactile_manip.learning.cvae.train import TrainConfig, train
cfg = TrainConfig(preset="small", norm="group", batch_size=8, lr=3e-3, epochs=2, patience=50, threads=1, seed=3)
train(cfg, sys.argv[1], sys.argv[2])
"""


@pytest.mark.slow
def test_two_gloo_processes_match_one_process(tiny_data, tmp_path):
    # GroupNorm: on CPU, BatchNorm statistics are per process (SyncBatchNorm needs a GPU), so exact
    # equivalence is a property of the data-parallel machinery with batch-independent normalisation.
    script = tmp_path / "run.py"
    script.write_text(SCRIPT)
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    single = subprocess.run([sys.executable, str(script), str(tiny_data), str(tmp_path / "one")], env=env,
                            capture_output=True, text=True, timeout=300)
    assert single.returncode == 0, single.stderr[-2000:]
    ddp = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--nproc_per_node", "2",
                          "--master_port", "29517", str(script), str(tiny_data), str(tmp_path / "two")],
                         env=env, capture_output=True, text=True, timeout=300)
    assert ddp.returncode == 0, ddp.stderr[-3000:]
    a, _, _ = load_checkpoint(tmp_path / "one" / "checkpoint.pt")
    b, _, _ = load_checkpoint(tmp_path / "two" / "checkpoint.pt")
    assert a.cfg.norm == "group"
    # The bias of a transposed convolution that feeds a one-channel-per-group GroupNorm has a gradient of
    # exactly zero up to rounding, which Adam turns into lr-sized steps of either sign: skip those.
    redundant = {n for n, m in a.named_modules() if isinstance(m, torch.nn.ConvTranspose2d)}
    pairs = [(n, pa, pb) for (n, pa), (_, pb) in zip(a.named_parameters(), b.named_parameters())
             if not (n.endswith(".bias") and n[:-5] in redundant)]
    worst = max(float((pa - pb).detach().abs().max()) for _, pa, pb in pairs)
    assert len(pairs) > 20 and worst < 1e-4
    assert any(float(p.detach().abs().sum()) > 0 for _, p, _ in pairs)
