"""Pairing by time: never beyond the tolerance, always the nearest frame, for adversarial timestamps."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_manip.collection.sync import DeviceClock, StreamPairer, nearest_within

# Times on a 0.5 ms grid make exact ties and duplicates likely; floats anywhere in [0, 1] s make near-ties.
grid_times = st.lists(st.integers(0, 400).map(lambda k: k * 0.0005), max_size=40)
float_times = st.lists(st.floats(0.0, 1.0, allow_nan=False), max_size=40)
times = st.one_of(grid_times, float_times)
tolerances = st.sampled_from([0.0, 0.001, 0.004, 0.005, 0.0165])


def _brute(q: float, ref: list[float], tol: float) -> int:
    if not ref:
        return -1
    d = [abs(q - r) for r in ref]
    best = min(d)
    if best > tol:
        return -1
    candidates = [i for i, x in enumerate(d) if x == best]
    return min(candidates, key=lambda i: (ref[i], i))  # ties: the earlier frame, then the lower index


@settings(max_examples=300, deadline=None)
@given(times, times, tolerances)
def test_nearest_within_is_the_brute_force_nearest_and_never_beyond_the_tolerance(query, ref, tol):
    got = nearest_within(query, ref, tol)
    for q, i in zip(query, got):
        expected = _brute(q, ref, tol)
        assert (i < 0) == (expected < 0)
        if i >= 0:
            assert abs(q - ref[i]) == abs(q - ref[expected]) <= tol  # the nearest (ties: any of equal distance)


def test_ties_between_neighbours_go_to_the_earlier_frame():
    assert nearest_within([1.0, 2.0], [2.5, 1.5, 0.5, 1.5], 0.5).tolist() == [2, 1]


@settings(max_examples=200, deadline=None)
@given(grid_times, times, tolerances, st.randoms(use_true_random=False))
def test_stream_pairer_matches_the_offline_rule_in_any_interleaving(field_times, depth_times, tol, rnd):
    """Magnetic frames arrive in time order (one stream); depth frames interleave anywhere."""
    field_times = sorted(field_times)
    merged = [("f", t) for t in field_times]
    for t in depth_times:  # the magnetic stream stays in order; each depth frame arrives anywhere in it
        merged.insert(rnd.randint(0, len(merged)), ("d", t))
    pairer, matches = StreamPairer(tol), []
    for kind, t in merged:
        if kind == "f":
            pairer.add_field(t, t)
        else:
            pairer.add_depth(t, t)
        matches += pairer.resolve()
    matches += pairer.resolve(flush=True)
    assert len(matches) == len(depth_times)
    for m in matches:
        expected = _brute(m.t_depth_s, field_times, tol)
        if expected < 0:
            assert not m.paired
        else:
            nearest = abs(field_times[expected] - m.t_depth_s)
            assert m.paired and abs(m.t_field_s - m.t_depth_s) == pytest.approx(nearest)
            assert abs(m.dt_s) <= tol


@settings(max_examples=200, deadline=None)
@given(times, times, tolerances)
def test_stream_pairer_never_pairs_beyond_the_tolerance_even_with_out_of_order_frames(field_times, depth_times, tol):
    pairer, matches = StreamPairer(tol), []
    for k in range(max(len(field_times), len(depth_times))):
        if k < len(field_times):
            pairer.add_field(field_times[k], k)
        if k < len(depth_times):
            pairer.add_depth(depth_times[k], k)
        matches += pairer.resolve()
    matches += pairer.resolve(flush=True)
    assert len(matches) == len(depth_times)
    assert all(abs(m.dt_s) <= tol for m in matches if m.paired)


def test_jittered_camera_and_lossy_magnetic_stream_pair_within_half_a_period():
    """30 Hz camera with 3 ms jitter and 20 % drops against 125 Hz with 10 % lost frames."""
    rng = np.random.default_rng(0)
    field = np.arange(0, 10, 0.008)
    field = field[rng.random(field.size) > 0.1]
    depth = np.arange(0.01, 10, 1 / 30)
    depth = depth + rng.normal(0, 0.003, depth.size)
    depth = depth[rng.random(depth.size) > 0.2]
    idx = nearest_within(depth, field, 0.005)
    dt = np.abs(field[idx[idx >= 0]] - depth[idx >= 0])
    assert dt.max() <= 0.005
    assert 0.85 < np.mean(idx >= 0) < 1.0  # a frame whose neighbours were lost stays unpaired


def test_bad_times_are_refused():
    with pytest.raises(ValueError, match="finite"):
        nearest_within([0.0, math.nan], [0.0], 0.01)
    with pytest.raises(ValueError, match="1-D"):
        nearest_within(np.zeros((2, 2)), [0.0], 0.01)
    with pytest.raises(ValueError, match="tolerance_s"):
        nearest_within([0.0], [0.0], -0.001)


def test_device_clock_undoes_usb_bursts_and_follows_a_restart():
    clock = DeviceClock()
    t0, period = 100.0, 0.008
    mapped, truth = [], []
    for k in range(400):
        sent = t0 + k * period
        arrival = t0 + (k // 4 * 4 + 3) * period + 0.0005  # delivered four at a time, 0.5 ms late
        mapped.append(clock.update(arrival, k * period))
        truth.append(sent)
        assert mapped[-1] <= arrival
    err = np.abs(np.array(mapped[8:]) - np.array(truth[8:]))
    assert err.max() < 0.001  # arrival times were off by up to 24.5 ms
    # the board restarts: its clock starts again at 0
    t1 = t0 + 400 * period + 0.5
    first = clock.update(t1 + 0.0005, 0.0)
    assert clock.resets == 1 and abs(first - t1) < 0.001
    assert clock.update(t1 + period + 0.0005, period) == pytest.approx(t1 + period + 0.0005, abs=1e-3)
