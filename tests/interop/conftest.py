"""Inputs for the exporters and viewers: episodes built directly from seeded random values (every stream filled
in, with some gaps), and real sources: a 10 s recording, a trial run of the README's scene (3 trials), a pair log."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tactile_manip.interop.frames import PHASES, Episode, Frame


def make_episodes(*, episodes: int = 2, frames: int = 40, depth_every: int = 10, fps: float = 125.0,
                  depth_shape: tuple[int, int] = (20, 24), seed: int = 0) -> list[Episode]:
    """``episodes`` trials of ``frames`` frames: fields of any sign, estimates on odd frames only, depth on
    every ``depth_every``-th frame, joints everywhere, phases in order, the VBTS depth on the first episode."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(episodes):
        host0 = 100.0 + 7.5 * k
        items = []
        for i in range(frames):
            odd = i % 2 == 1
            depth = rng.uniform(0, 1.5, depth_shape).astype(np.float32) if i % depth_every == 0 else None
            items.append(Frame(
                t_s=i / fps, host_time_s=host0 + i / fps + rng.uniform(0, 1e-3),
                field_ut=rng.normal(0, 80, (4, 4, 3)).astype(np.float32),
                angle_rad=float(rng.uniform(-math.pi / 2, math.pi / 2)) if odd else math.nan,
                confidence=float(rng.uniform(0, 1)) if odd else math.nan,
                joints_rad=rng.uniform(-2, 2, 7), gripper_width_m=float(rng.uniform(0, 0.08)),
                target_angle_rad=0.25 * k, phase=PHASES[1 + min(3, 4 * i // frames)], depth_mm=depth,
                vbts_depth_mm=depth + 0.5 if depth is not None and k == 0 else None))
        out.append(Episode(index=k, task=f"reorient rod to {15 * k} deg (supermag)", fps=fps, frames=items,
                           success=k % 2 == 0, meta={"layout": "supermag-4x4"}))
    return out


@pytest.fixture
def episodes() -> list[Episode]:
    return make_episodes()


REPO = Path(__file__).resolve().parents[2]
RATE_HZ = 125.0


def write_recording(path: Path, *, seconds: float = 10.0, seed: int = 0) -> Path:
    """A recording of ``seconds`` at 125 Hz through the recorder's own writer: idle chips, then a press."""
    from tactile_manip.wire.protocol import CountScale, encode_frame
    from tactile_manip.sensors.recording import RecordingWriter, recording_header
    from tactile_manip.sensors.simulated import SimulatedSensor

    rng = np.random.default_rng(seed)
    sensor = SimulatedSensor()  # not connected: only its description goes to the header
    scale = CountScale.from_chip(sensor.chip)
    idle = sensor.pair.to_reading(sensor.pair.baseline_field_ut)  # (4, 4, 3) uT
    n = int(round(seconds * RATE_HZ))
    with RecordingWriter(path, recording_header(sensor)) as out:
        for k in range(n):
            press = 150.0 * np.exp(-((k - n / 2) / 60.0) ** 2)  # a smooth press in the middle, uT on z
            field = idle + rng.normal(0.0, 2.0, idle.shape) + np.array([0.0, 0.0, press])
            wire = encode_frame(scale.to_counts(field.astype(np.float32)), seq=k, t_mcu_us=int(k * 8000), status=0)
            out.write_frame(1000.0 + k / RATE_HZ + rng.uniform(0, 1e-3), wire)
    return path


@pytest.fixture
def make_recording():
    """``make_recording(path, seconds=10.0, seed=0)``: a recording at 125 Hz (see :func:`write_recording`)."""
    return write_recording


@pytest.fixture(scope="session")
def recording(tmp_path_factory) -> Path:
    """A 10 s recording (1250 frames)."""
    return write_recording(tmp_path_factory.mktemp("rec") / "ten_seconds.tmrec")


@pytest.fixture(scope="session")
def trial_run(tmp_path_factory) -> Path:
    """``tactile-manip trials --config configs/scenes/reorient_sim.toml --trials 3 --methods
    supermag,supermag_sym,bilinear --out R`` (the model, the model symmetry-averaged, and the baseline)."""
    pytest.importorskip("roboticstoolbox", reason="the simulated trial cell needs roboticstoolbox-python")
    pytest.importorskip("onnxruntime", reason="the scene's model methods need onnxruntime")
    import os

    from tactile_manip.cli import main

    run = tmp_path_factory.mktemp("trials") / "R"
    cwd = os.getcwd()
    os.chdir(REPO)  # the scene names its model relative to the repository
    try:
        assert main(["trials", "--config", "configs/scenes/reorient_sim.toml", "--trials", "3", "--methods",
                     "supermag,supermag_sym,bilinear", "--out", str(run), "--quiet"]) == 0
    finally:
        os.chdir(cwd)
    return run


def write_pair_log(path: Path, objects: list[str], seed: int = 0) -> Path:
    """A pair log of one synthetic pair per name in ``objects`` (random field, random uint8 depth)."""
    from tactile_manip.collection.pair_log import PairLogWriter, PairRecord

    rng = np.random.default_rng(seed)
    with PairLogWriter(path, {"config": {"tolerance_s": 0.005}, "pixel_mm": 0.1}) as log:
        log.write_event(0.0, {"event": "start"})
        for k, obj in enumerate(objects):
            record = PairRecord(rng.normal(0, 50, (4, 4, 3)).astype(np.float32),
                                rng.normal(0, 50, (4, 4, 3)).astype(np.float32), np.zeros((4, 4, 3), bool),
                                rng.integers(0, 180, (200, 200)).astype(np.uint8),
                                {"t_depth_s": k * 0.1, "t_field_s": k * 0.1 + 0.002, "dt_s": 0.002, "seq_depth": k,
                                 "seq_field": 4 * k, "force_n": 10.2, "object": obj, "pose": None, "press": k})
            log.write_pair(k * 0.1, record)
    return path


@pytest.fixture
def pair_log(tmp_path) -> Path:
    return write_pair_log(tmp_path / "pairs.tmpairs", ["ball", "ball", "letter_r", "ball", "letter_r"])
