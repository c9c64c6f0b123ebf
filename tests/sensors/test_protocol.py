"""The wire codec: layout, CRC, round trips, resync, counters, and fuzzing of the stream decoder."""

from __future__ import annotations

import binascii
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tactile_manip.errors import ProtocolError
from tactile_manip.wire.protocol import (
    FRAME_LEN,
    FRAME_LEN_T,
    SYNC,
    CountScale,
    FrameDecoder,
    Unwrapper,
    crc16,
    decode_frame,
    encode_frame,
)

FUZZ = settings(max_examples=300, derandomize=True, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _frames(n: int, seed: int = 0, *, temperature: bool = False) -> list[bytes]:
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        temps = rng.integers(2000, 3000, (4, 4)) if temperature else None
        out.append(encode_frame(rng.integers(-32768, 32768, (4, 4, 3)), seq=i, t_mcu_us=8000 * i,
                                status=i % 3, temperature_raw=temps))
    return out


def _crc_ok(raw: bytes) -> bool:
    return binascii.crc_hqx(raw[2:-2], 0xFFFF) == struct.unpack("<H", raw[-2:])[0]


def _accounted(d: FrameDecoder, frames) -> bool:
    """Every byte fed is in a frame, skipped, or pending."""
    return sum(len(f.raw) for f in frames) + d.stats.resync_bytes + d.pending == d.stats.bytes_in


def test_crc_is_ccitt_false():
    assert crc16(b"123456789") == 0x29B1


def test_layout_matches_the_design_table():
    counts = np.arange(48, dtype=np.int16).reshape(4, 4, 3) - 24
    raw = encode_frame(counts, seq=0x1234, t_mcu_us=0xDEADBEEF, status=0x0102)
    assert len(raw) == FRAME_LEN == 110
    assert raw[:2] == b"\xaa\x55" and raw[2] == 1 and raw[3] == 0
    assert raw[4:6] == b"\x34\x12" and raw[6:10] == bytes.fromhex("efbeadde") and raw[10:12] == b"\x02\x01"
    # chip order row-major over (row, col), axes x, y, z, int16 little-endian
    assert np.array_equal(np.frombuffer(raw[12:108], "<i2"), counts.ravel())
    assert raw[108:110] == struct.pack("<H", crc16(raw[2:108]))


def test_round_trip_with_and_without_temperatures():
    counts = np.random.default_rng(1).integers(-32768, 32768, (4, 4, 3))
    temps = np.full((4, 4), 2512)
    for t in (None, temps):
        raw = encode_frame(counts, seq=70000, t_mcu_us=2**32 + 5, status=7, temperature_raw=t)
        f = decode_frame(raw)
        assert len(raw) == (FRAME_LEN if t is None else FRAME_LEN_T)
        assert np.array_equal(f.counts, counts) and f.counts.shape == (4, 4, 3)
        assert f.seq == 70000 % 65536 and f.t_mcu_us == 5 and f.status == 7 and f.raw == raw
        assert (f.temperature_raw is None) if t is None else np.array_equal(f.temperature_raw, temps)


@pytest.mark.parametrize("counts, kwargs, match", [
    (np.zeros((4, 4, 2), int), {}, "shape"),
    (np.full((4, 4, 3), 40000), {}, "int16"),
    (np.zeros((4, 4, 3)), {}, "integers"),
    (np.zeros((4, 4, 3), int), {"status": 70000}, "u16"),
    (np.zeros((4, 4, 3), int), {"temperature_raw": np.zeros(16, int)}, "temperature"),
])
def test_encode_refuses_values_that_do_not_fit(counts, kwargs, match):
    with pytest.raises(ProtocolError, match=match):
        encode_frame(counts, seq=0, t_mcu_us=0, **kwargs)


def test_decode_frame_names_what_is_wrong():
    raw = _frames(1)[0]
    with pytest.raises(ProtocolError, match="CRC"):
        decode_frame(raw[:50] + bytes([raw[50] ^ 1]) + raw[51:])
    with pytest.raises(ProtocolError, match="110 bytes"):
        decode_frame(raw[:-1])
    with pytest.raises(ProtocolError, match="version 9"):
        decode_frame(raw[:2] + b"\x09" + raw[3:])
    with pytest.raises(ProtocolError, match="sync"):
        decode_frame(b"\x00" + raw[1:])


def test_decoder_resyncs_after_garbage_and_counts_it():
    frames = _frames(5)
    stream = b"\x01\xaa\x02" + frames[0] + frames[1][:40] + frames[2] + b"\xaa\x55\x07junk" + frames[3] + frames[4]
    d = FrameDecoder()
    got = d.feed(stream)
    assert [f.seq for f in got] == [0, 2, 3, 4]
    assert d.stats.frames == 4 and d.stats.crc_errors >= 1 and d.stats.version_errors == 1
    assert d.stats.resync_bytes == 3 + 40 + 7 and d.pending == 0
    assert _accounted(d, got)


def test_a_sync_split_across_reads_is_kept():
    raw = _frames(1)[0]
    d = FrameDecoder()
    assert d.feed(b"\x00\x00" + raw[:1]) == [] and d.pending == 1
    assert [f.seq for f in d.feed(raw[1:])] == [0]
    assert d.stats.resync_bytes == 2


def test_reset_drops_pending_bytes_as_resync():
    d = FrameDecoder()
    d.feed(_frames(1)[0][:60])
    d.reset()
    assert d.pending == 0 and d.stats.resync_bytes == 60


def test_unwrapper_unwraps_and_survives_restarts():
    u = Unwrapper(16)
    values = [u.update(s) for s in (65534, 65535, 0, 1, 3)]
    assert [v for v, _ in values] == [65534, 65535, 65536, 65537, 65539]
    assert [s for _, s in values] == [1, 1, 1, 1, 2]
    assert u.update(3) == (65540, 0)          # a repeat: reported as step 0, value still increases
    assert u.update(0) == (65541, -3)         # backwards (device restart)


def test_count_scale_uses_the_chip_lsbs_and_round_trips():
    scale = CountScale(0.200, 0.323, 32767)
    counts = np.array([[100, -100, 1000]], dtype=np.int16)
    ut = scale.to_ut(counts)
    assert ut.dtype == np.float32 and np.allclose(ut, [[20.0, -20.0, 323.0]])
    assert np.array_equal(scale.to_counts(ut), counts)
    assert scale.saturated(np.array([32767, -32767, -32768, 0], np.int16)).tolist() == [True, True, True, False]


# ---------------------------------------------------------------- fuzzing

@FUZZ
@given(data=st.binary(max_size=3000), cuts=st.lists(st.integers(0, 3000), max_size=8))
def test_random_bytes_never_crash_and_yield_only_crc_valid_frames(data, cuts):
    d = FrameDecoder()
    got = []
    for a, b in zip([0, *sorted(cuts)], [*sorted(cuts), len(data)]):
        got += d.feed(data[a:b])
    assert all(len(f.raw) in (FRAME_LEN, FRAME_LEN_T) and f.raw[:2] == SYNC and _crc_ok(f.raw) for f in got)
    assert d.pending <= FRAME_LEN_T and _accounted(d, got)


@FUZZ
@given(n=st.integers(1, 6), flips=st.lists(st.integers(0, 6 * FRAME_LEN_T * 8 - 1), min_size=1, max_size=3),
       temperature=st.booleans())
def test_bit_flips_lose_only_the_damaged_frames(n, flips, temperature):
    frames = _frames(n, temperature=temperature)
    stream = bytearray(b"".join(frames))
    for bit in flips:
        bit %= len(stream) * 8
        stream[bit // 8] ^= 1 << (bit % 8)
    length = len(frames[0])
    damaged = {i for i, f in enumerate(frames) if stream[i * length:(i + 1) * length] != f}
    got = FrameDecoder().feed(bytes(stream))
    # CRC-16/CCITT detects every 1-3 bit error: nothing damaged gets through, nothing undamaged is lost
    # (a flip in a flags byte makes its own frame look longer; that candidate fails its CRC)
    assert all(f.raw in frames for f in got)
    assert {f.seq for f in got} == set(range(n)) - damaged


@FUZZ
@given(n=st.integers(2, 6), cut_frame=st.integers(0, 5), keep=st.integers(1, FRAME_LEN - 1),
       drop=st.integers(0, FRAME_LEN - 1))
def test_truncated_or_shortened_frames_are_rejected_and_the_rest_decodes(n, cut_frame, keep, drop):
    frames = _frames(n)
    i = cut_frame % n
    for damaged in (frames[i][:keep], frames[i][:drop] + frames[i][drop + 1:]):
        stream = b"".join(frames[:i]) + damaged + b"".join(frames[i + 1:])
        d = FrameDecoder()
        got = d.feed(stream)
        assert all(_crc_ok(f.raw) for f in got) and _accounted(d, got)
        assert [f.seq for f in got] == [k for k in range(n) if k != i]


@FUZZ
@given(n=st.integers(1, 5), cuts=st.lists(st.integers(0, 5 * FRAME_LEN), max_size=10), junk=st.binary(max_size=50))
def test_chunking_does_not_change_the_result(n, cuts, junk):
    stream = junk + b"".join(_frames(n)) + junk
    whole = FrameDecoder()
    expected = whole.feed(stream)
    d = FrameDecoder()
    got = []
    for a, b in zip([0, *sorted(cuts)], [*sorted(cuts), len(stream)]):
        got += d.feed(stream[a:b])
    assert [f.raw for f in got] == [f.raw for f in expected]
    assert d.stats == whole.stats
