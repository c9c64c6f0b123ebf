"""The AnySkin wire decoder: framing by CRLF and length, resync after noise, never a wrong frame, never a raise."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tactile_manip.errors import ProtocolError
from tactile_manip.boards import board_names, load_board
from tactile_manip.wire import WIRE_FORMATS, make_decoder
from tactile_manip.wire.anyskin import AnySkinDecoder, frame_length
from tactile_manip.chips import MLX90393

N_CHIPS = 5
LEN = frame_length(N_CHIPS)


def published_frame(values: np.ndarray) -> bytes:
    """(n_chips, 4) t, x, y, z as the published sketch writes them: raw float32 structs, then println's CRLF."""
    return b"".join(struct.pack("<4f", *row) for row in values) + b"\r\n"


def stream(n: int, seed: int = 0) -> tuple[list[np.ndarray], bytes]:
    rng = np.random.default_rng(seed)
    frames = []
    for _ in range(n):
        v = np.empty((N_CHIPS, 4), np.float32)
        v[:, 0] = rng.uniform(20.0, 40.0, N_CHIPS)
        v[:, 1:] = rng.normal(0.0, 500.0, (N_CHIPS, 3))
        frames.append(v)
    return frames, b"".join(published_frame(v) for v in frames)


def test_frame_length_follows_the_chip_count():
    assert LEN == 82 and frame_length(1) == 18


def test_in_sync_stream_decodes_exactly_with_temperatures_and_no_counter():
    values, data = stream(20)
    d = AnySkinDecoder(n_chips=N_CHIPS)
    frames = d.feed(b"\r\n" + data)  # a line ending before the first frame, as mid-stream
    assert len(frames) == 20
    for v, f in zip(values, frames):
        np.testing.assert_array_equal(f.field_ut, v[:, 1:])
        np.testing.assert_array_equal(f.temperature_c, v[:, 0])
        assert f.seq is None and f.t_device_us is None and f.status == 0 and len(f.raw) == LEN
    assert d.stats.frames == 20 and d.stats.frame_errors == 0 and d.stats.resync_bytes == 2 and d.pending == 0


def test_decode_record_reads_a_stored_frame_and_refuses_others():
    values, data = stream(1)
    d = AnySkinDecoder(n_chips=N_CHIPS)
    np.testing.assert_array_equal(d.decode_record(data).field_ut, values[0][:, 1:])
    with pytest.raises(ProtocolError, match="82 bytes"):
        d.decode_record(data[:-1])
    with pytest.raises(ProtocolError, match="not a valid"):
        d.decode_record(data[:-2] + b"\n\r")


def test_saturated_channels_are_flagged_at_the_counts_rail():
    chip = MLX90393
    v = np.zeros((N_CHIPS, 4), np.float32)
    v[:, 0] = 25.0
    v[2, 3] = chip.saturation_counts * chip.lsb_z_ut  # z of chip 2 at the rail
    f = AnySkinDecoder(n_chips=N_CHIPS, chip=chip).feed(b"\r\n" + published_frame(v) * 2)[0]
    assert f.saturated.sum() == 1 and f.saturated[2, 2]


def test_the_format_table_names_importable_decoders():
    for name in WIRE_FORMATS:
        n = 16 if name == "supermag" else N_CHIPS
        assert make_decoder(name, n_chips=n, chip=MLX90393).name == name
    with pytest.raises(ValueError, match="known formats: supermag, anyskin"):
        make_decoder("reskin-ascii", n_chips=5, chip=MLX90393)
    assert set(board_names()) == {"supermag-4x4", "anyskin-5", "eflesh"} and load_board("anyskin-5").n_chips == N_CHIPS


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.binary(max_size=2000), cuts=st.lists(st.integers(0, 2000), max_size=8))
def test_arbitrary_bytes_never_raise_and_every_byte_is_accounted_for(data, cuts):
    d = AnySkinDecoder(n_chips=N_CHIPS)
    bounds = sorted({0, len(data), *[c for c in cuts if c <= len(data)]})
    frames = [f for a, b in zip(bounds, bounds[1:]) for f in d.feed(data[a:b])]
    st_ = d.stats
    assert st_.bytes_in == len(data)
    assert len(frames) * LEN + st_.resync_bytes + d.pending == len(data)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(noise=st.binary(max_size=400), cut=st.integers(0, 20 * LEN), inject_at=st.integers(3, 15),
       chunk=st.integers(1, 200))
def test_after_noise_it_resyncs_and_never_yields_a_wrong_frame(noise, cut, inject_at, chunk):
    values, data = stream(20, seed=1)
    # noise at the start (a port opened mid-frame) and again in the middle, after a truncated frame
    mid = inject_at * LEN
    damaged = noise + data[:mid] + data[mid:mid + cut % LEN] + noise + data[mid + LEN:]
    d = AnySkinDecoder(n_chips=N_CHIPS)
    frames = [f for i in range(0, len(damaged), chunk) for f in d.feed(damaged[i:i + chunk])]
    index = {v.tobytes(): k for k, v in enumerate(values)}
    got = [index.get(np.frombuffer(f.raw[:-2], "<f4").reshape(N_CHIPS, 4).tobytes()) for f in frames]
    assert None not in got                                  # every frame yielded is one that was sent
    assert got == sorted(set(got))                          # in order, no repeats
    # at most the first frame after each noise burst, and the cut frame, can be lost (1 + 2 + 1 frames)
    assert inject_at not in got and len(got) >= 20 - 4
    assert set(range(inject_at + 3, 20)) <= set(got) and set(range(2, inject_at)) <= set(got)
