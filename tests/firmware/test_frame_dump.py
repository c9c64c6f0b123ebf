"""The firmware's C frame encoder, built for the host, against the driver's Python decoder and encoder.

``make -C firmware host`` builds ``frame_dump``; its bytes must decode to the self-test pattern documented
in ``firmware/supermag/frame.h`` and be byte-identical to what ``protocol.encode_frame`` makes of that
pattern. The ESP32 sketch itself is built only where PlatformIO is installed.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from tactile_manip.wire.protocol import FRAME_LEN, FRAME_LEN_T, FrameDecoder, encode_frame

FIRMWARE = Path(__file__).resolve().parents[2] / "firmware"


def self_test_pattern(k: int, *, temperature: bool) -> dict:
    """Frame ``k`` of the pattern exactly as frame.h documents it."""
    c = np.arange(16)[:, None]
    a = np.arange(3)[None, :]
    counts = ((k * 97 + c * 1000 + a * 331) & 0xFFFF).astype(np.uint16).view(np.int16).reshape(4, 4, 3)
    temps = (2500 + 10 * np.arange(16) + k % 50).astype(np.int16).reshape(4, 4) if temperature else None
    return {"seq": k & 0xFFFF, "t_mcu_us": (k * 8000) & 0xFFFFFFFF,
            "status": (1 << (k % 16)) if k % 8 == 7 else 0, "counts": counts, "temperature_raw": temps}


@pytest.fixture(scope="module")
def frame_dump(tmp_path_factory) -> Path:
    if shutil.which("gcc") is None:
        pytest.skip("the host build of the firmware needs gcc on PATH")
    build = tmp_path_factory.mktemp("firmware_build")
    if shutil.which("make") is not None:  # the documented command
        subprocess.run(["make", "-C", str(FIRMWARE), "host", f"BUILD={build}"], check=True, capture_output=True)
    else:  # a machine with gcc but no make: the Makefile's one compile line
        subprocess.run(["gcc", "-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-pedantic",
                        f"-I{FIRMWARE / 'supermag'}", "-o", str(build / "frame_dump"),
                        str(FIRMWARE / "host" / "frame_dump.c"), str(FIRMWARE / "supermag" / "frame.c")],
                       check=True, capture_output=True)
    return build / "frame_dump"


@pytest.mark.parametrize("temperature", [False, True])
def test_frame_dump_decodes_to_the_documented_pattern_byte_for_byte(frame_dump, temperature):
    n = 300  # crosses the status pattern and the int16 sign boundary many times
    args = [str(frame_dump), str(n)] + (["--temperature"] if temperature else [])
    data = subprocess.run(args, check=True, capture_output=True).stdout
    assert len(data) == n * (FRAME_LEN_T if temperature else FRAME_LEN)
    decoder = FrameDecoder()
    frames = decoder.feed(data)
    assert len(frames) == n and decoder.stats.crc_errors == 0 and decoder.stats.resync_bytes == 0
    for k, f in enumerate(frames):
        want = self_test_pattern(k, temperature=temperature)
        assert (f.seq, f.t_mcu_us, f.status) == (want["seq"], want["t_mcu_us"], want["status"])
        np.testing.assert_array_equal(f.counts, want["counts"])
        if temperature:
            np.testing.assert_array_equal(f.temperature_raw, want["temperature_raw"])
        else:
            assert f.temperature_raw is None
        assert f.raw == encode_frame(**want)  # the Python encoder makes the very same bytes


def test_frame_dump_wraps_seq_and_clock_like_the_device(frame_dump):
    # 2**16 + 2 frames: the u16 sequence wraps to 0 and the clock keeps the 8 ms schedule
    n = (1 << 16) + 2
    data = subprocess.run([str(frame_dump), str(n)], check=True, capture_output=True).stdout
    last = FrameDecoder().feed(data[-2 * FRAME_LEN:])
    assert [f.seq for f in last] == [0, 1]
    assert [f.t_mcu_us for f in last] == [(n - 2) * 8000, (n - 1) * 8000]


def test_frame_dump_refuses_a_bad_count(frame_dump):
    out = subprocess.run([str(frame_dump), "many"], capture_output=True, text=True)
    assert out.returncode == 2 and "frame count" in out.stderr


def test_the_esp32_sketch_builds(tmp_path):
    pio = shutil.which("pio") or shutil.which("platformio")
    arduino = shutil.which("arduino-cli")
    if pio is None and arduino is None:
        pytest.skip("neither PlatformIO (`pio`) nor `arduino-cli` is installed; the ESP32 toolchain cannot be "
                    "downloaded here (firmware/README.md says how to build the sketch)")
    if pio is not None:
        runs = [([pio, "run", "-d", str(FIRMWARE), "-e", env], {"PLATFORMIO_BUILD_DIR": str(tmp_path / env)})
                for env in ("esp32dev", "esp32dev-selftest")]
    else:
        runs = [([arduino, "compile", "--fqbn", "esp32:esp32:esp32", "--build-path", str(tmp_path / "arduino"),
                  str(FIRMWARE / "supermag")], {})]
    for cmd, env in runs:
        out = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, **env})
        assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-4000:]
