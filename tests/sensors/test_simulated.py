"""The simulated sensor: true contacts put on it, scripted presses, stalls, determinism, baseline refusal."""

from __future__ import annotations

import time

import numpy as np
import pytest

from tactile_manip.errors import CalibrationError, SensorTimeoutError
from tactile_manip.sensors import Press, SimulatedSensor, SimulatedSensorConfig
from tactile_manip.sensors.simulated.contacts import ContactTimeline, parse_press
from tactile_manip.sim.objects import IndenterPose
from tactile_manip.sim.pair import SensorPair
from tactile_manip.sim.shapes import make_indenter


@pytest.fixture(scope="module")
def pair():
    return SensorPair()


def test_set_contact_puts_the_true_field_on_the_readings(pair, monkeypatch):
    r_obj, pose = make_indenter("letter_r"), IndenterPose(x_mm=0.5, yaw_rad=0.3)
    truth = pair.press(r_obj, pose, 10.0, np.random.default_rng(0), render_depth=False).field_change_ut
    solves = []
    solve = pair.press
    monkeypatch.setattr(pair, "press", lambda *args, **kwargs: solves.append(args) or solve(*args, **kwargs))
    with SimulatedSensor(pair=pair) as s:
        s.set_baseline(s.expected_baseline_ut)
        idle = s.wait_new(2.0)
        assert np.abs(idle.field_ut).max() < 15.0                     # noise (and quantisation) only
        change = s.set_contact(r_obj, pose, 10.0)
        assert len(solves) == 1                                       # the first call solves the contact
        assert np.allclose(change, truth)
        assert np.allclose(s.contact_field_ut, truth)
        s.read_latest(1.0)
        pressed = np.mean([s.wait_new(2.0).field_ut for _ in range(10)], axis=0)
        assert np.abs(pressed - truth).max() < 5.0                    # truth + zero-mean noise
        again = s.set_contact(r_obj, pose, 10.0)
        assert len(solves) == 1 and np.array_equal(again, change)     # cached: no second solve, the same field
        s.set_contact(r_obj, pose, 10.5)
        assert len(solves) == 2                                       # another force is another contact
        s.clear_contact()
        s.read_latest(1.0)
        assert np.abs(s.wait_new(2.0).field_ut).max() < 15.0


def test_no_frame_after_clear_contact_returns_carries_the_contact(pair, monkeypatch):
    import threading

    bar, pose = make_indenter("hex_bar", size_mm=4.0), IndenterPose(yaw_rad=0.5)
    with SimulatedSensor(pair=pair) as s:
        s.set_baseline(s.expected_baseline_ut)
        s.set_contact(bar, pose, 10.0)
        s.read_latest(1.0)
        assert np.abs(s.wait_new(2.0).field_ut).max() > 50.0  # the bar is on the pad
        measuring, chips = threading.Event(), pair.chips

        class SlowChips:  # the next frame is measured with the bar still on, and takes 0.2 s to come out
            def __getattr__(self, name):
                return getattr(chips, name)

            def measure(self, field, rng):
                measuring.set()
                time.sleep(0.2)
                return chips.measure(field, rng)
        monkeypatch.setattr(pair, "chips", SlowChips())
        assert measuring.wait(2.0)
        s.clear_contact()  # returns once the frame in flight is out
        monkeypatch.setattr(pair, "chips", chips)
        with s.subscribe() as frames:  # every frame published from now on
            assert all(np.abs(frames.get(2.0).reading.field_ut).max() < 15.0 for _ in range(3))


def test_a_contact_that_bottoms_out_is_refused(pair):
    from tactile_manip.errors import SimulationError

    with SimulatedSensor(pair=pair) as s:
        with pytest.raises(SimulationError, match="bottoms out"):
            s.set_contact(make_indenter("letter_r"), IndenterPose(), 1e6)
        assert s.contact_field_ut is None or not np.any(s.contact_field_ut)  # nothing was put on the pad


def test_same_seed_same_frames_other_seed_other_frames(pair):
    def first_frames(seed):
        s = SimulatedSensor(SimulatedSensorConfig(seed=seed), pair=pair)
        with s.subscribe() as sub:
            with s:
                frames = [sub.get(2.0).reading for _ in range(15)]
        return {r.seq: r.field_raw_ut for r in frames}

    a, b, c = first_frames(4), first_frames(4), first_frames(5)
    assert a.keys() == b.keys() == set(range(15))
    assert all(np.array_equal(a[k], b[k]) for k in a)
    assert not any(np.array_equal(a[k], c[k]) for k in a)


def test_stall_and_resume(pair):
    with SimulatedSensor(pair=pair) as s:
        s.wait_new(2.0)
        s.stall()
        assert s.stalled and not s.health().link_up
        time.sleep(0.25)
        with pytest.raises(SensorTimeoutError, match=r"stalled: call resume\(\)"):
            s.read_latest(max_age_s=0.1)
        s.resume()
        r = s.wait_new(2.0)
        assert s.read_latest(0.2).seq >= r.seq and s.health().seq_gaps == 0


def test_baseline_is_accepted_idle_and_refused_during_a_press(pair):
    with SimulatedSensor(pair=pair) as s:
        b = s.calibrate_baseline(40)
        assert np.abs(b.offset_ut - s.expected_baseline_ut).max() < 3.0
        assert np.all(b.noise_ut[..., :2] < 3.0) and np.all(b.noise_ut[..., 2] < 4.5)
        s.play([Press("letter_r", start_s=0.0, peak_force_n=10.0, rise_s=0.5, hold_s=0.2)])
        with pytest.raises(CalibrationError, match="touching the pad"):
            s.calibrate_baseline(40)
        assert s.baseline is b                                        # the refused one is not used


def test_a_scripted_press_ramps_up_holds_and_releases(pair):
    press = Press("cylinder", start_s=0.1, peak_force_n=8.0, rise_s=0.2, hold_s=0.1, object_kwargs={"size_mm": 4.0})
    tl = ContactTimeline(pair, [press])
    assert tl.force_at(0.05) == 0.0 and tl.force_at(0.2) == pytest.approx(4.0) and tl.force_at(0.35) == 8.0
    assert np.abs(tl.change_at(0.05)).max() == 0.0
    peak = np.abs(tl.change_at(0.35)).max()
    assert 50.0 < peak < 500.0 and np.abs(tl.change_at(0.2)).max() < peak
    assert np.allclose(tl.change_at(0.35), pair.press(make_indenter("cylinder", size_mm=4.0), IndenterPose(), 8.0,
                                                     np.random.default_rng(0)).field_change_ut)
    looped = ContactTimeline(pair, [press], period_s=1.0)
    assert np.allclose(looped.change_at(2.35), tl.change_at(0.35))


def test_press_specs_and_overlaps_are_checked(pair):
    p = parse_press("letter_r,t=1.5,force=9,x=0.5,y=-1,yaw=90,rise=0.3,hold=0.2")
    assert (p.name, p.start_s, p.peak_force_n, p.rise_s, p.hold_s) == ("letter_r", 1.5, 9.0, 0.3, 0.2)
    assert p.pose.x_mm == 0.5 and p.pose.y_mm == -1.0 and p.pose.yaw_rad == pytest.approx(np.pi / 2)
    for bad, match in [("", "object name"), ("teapot", "unknown object"), ("letter_r,t", "key=number"),
                       ("letter_r,speed=3", "unknown key"), ("letter_r,force=-1", "peak_force_n")]:
        with pytest.raises(ValueError, match=match):
            parse_press(bad)
    with pytest.raises(ValueError, match="overlap"):
        ContactTimeline(pair, [Press("letter_r", start_s=0.0), Press("allen_key", start_s=0.5)])


def test_a_replaced_pair_is_read_and_baselined_at_its_own_chip_noise():
    import dataclasses

    from tactile_manip.sensors.simulated import SimulatedSensor
    from tactile_manip.sim.pair import SensorPair
    from tactile_manip.sim.params import SimParams

    params = SimParams()
    noisy = dataclasses.replace(params, chip=dataclasses.replace(params.chip, noise_xy_ut=14.0, noise_z_ut=14.0),
                                magnet=dataclasses.replace(params.magnet, remanence_t=0.035))
    with SimulatedSensor() as sensor:
        sensor.calibrate_baseline(frames=25)
        sensor.replace_pair(SensorPair(noisy))
        assert sensor.chip.noise_xy_ut == 14.0
        base = sensor.calibrate_baseline(frames=25)  # refused at the nominal chip's 9 uT threshold
        assert float(base.noise_ut.max()) > 9.0
        assert abs(float(sensor.wait_new(timeout_s=1.0).field_ut.mean())) < 15.0
