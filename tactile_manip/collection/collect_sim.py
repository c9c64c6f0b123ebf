"""The simulated collection rig: the emulated MBTS board and the simulated VBTS camera on one press script.

:class:`SimulatedRig` runs the firmware emulator on a pseudo-terminal (real bytes at 125 Hz, faults
injectable), reads it with the real serial driver, renders the camera from the same
:class:`~tactile_manip.sim.pair.SensorPair`, and gives the collector the script's force as the gripper's. The
emulator's clock starts when it starts streaming; the rig finds that instant on the host clock as the
smallest ``t_host - t_device`` of the first frames (the frame that arrived fastest), and starts the camera's
script and the force there, so all three agree to well under a millisecond.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Sequence

import numpy as np

from tactile_manip.errors import SensorTimeoutError
from tactile_manip.collection.camera_sim import SimulatedCamera, SimulatedCameraConfig, ball_indenter
from tactile_manip.collection.force import ScriptForce
from tactile_manip.sensors.config import SerialSensorConfig
from tactile_manip.sensors.simulated.contacts import Press
from tactile_manip.sensors.simulated.emulator import EmulatorConfig, FaultConfig, FirmwareEmulator
from tactile_manip.sensors.serial_sensor import SerialSensor
from tactile_manip.collection.vbts import DepthParams
from tactile_manip.collection.vbts_calibration import VbtsCalibration, calibrate_ball
from tactile_manip.sim.objects import IndenterPose
from tactile_manip.sim.pair import SensorPair

ORIGIN_FRAMES = 25  # MBTS frames used to find the emulator's start on the host clock


def random_presses(objects: Sequence[str], count: int, *, rng: np.random.Generator, lead_s: float = 3.0,
                   rise_s: float = 0.15, hold_s: float = 0.25, gap_s: float = 0.1,
                   peak_force_n: tuple[float, float] = (10.0, 11.0), offset_mm: float = 4.0,
                   tilt_deg: float = 0.0) -> list[Press]:
    """``count`` presses cycling over ``objects``, at random offsets and yaws, one after another.

    The peak force is drawn from ``peak_force_n`` (the 10 N threshold plus the gripper's overshoot); the
    first press starts at ``lead_s`` (room for the baseline and the reference).
    """
    if not objects:
        raise ValueError("objects: name at least one object to press")
    presses, t = [], lead_s
    for i in range(count):
        tilt = math.radians(tilt_deg)
        pose = IndenterPose(x_mm=rng.uniform(-offset_mm, offset_mm), y_mm=rng.uniform(-offset_mm, offset_mm),
                            yaw_rad=rng.uniform(-math.pi, math.pi), tilt_x_rad=rng.uniform(-tilt, tilt),
                            tilt_y_rad=rng.uniform(-tilt, tilt))
        p = Press(objects[i % len(objects)], start_s=t, peak_force_n=rng.uniform(*peak_force_n), pose=pose,
                  rise_s=rise_s, hold_s=hold_s)
        presses.append(p)
        t = p.end_s + gap_s
    return presses


def calibrate_simulated(camera: SimulatedCamera, *, radius_mm: float = 4.0, force_n: float = 3.0, frames: int = 10,
                        pose: IndenterPose | None = None, params: DepthParams | None = None) -> VbtsCalibration:
    """Ball-press calibration on a connected simulated camera (reference, then a still press of the ball)."""
    camera.clear_contact()
    reference = _frames_after(camera, time.monotonic(), frames)
    camera.set_contact(ball_indenter(radius_mm), pose or IndenterPose(), force_n)
    press = _frames_after(camera, time.monotonic(), frames)
    camera.clear_contact()
    return calibrate_ball(camera.alignment, reference, [press], radius_mm, params=params)


def _frames_after(camera: SimulatedCamera, t_host_s: float, n: int) -> list[np.ndarray]:
    out = []
    while len(out) < n:
        f = camera.read(2.0)
        if f.t_exposure_s > t_host_s:
            out.append(f.image)
    return out


class SimulatedRig:
    """Emulated MBTS (firmware emulator on a pty + :class:`SerialSensor`), simulated camera and script force.

    Use as a context manager; inside, ``sensor`` and ``camera`` are connected and ``force`` runs on their clock.

    Args:
        presses: the press script (script time 0 = the emulator's first frame).
        seed: sensor constants, chip noise and camera noise.
        camera: the simulated camera's settings (jitter, drops, true lookup table, ...).
        faults: faults the emulated board injects (bit flips, dropped bytes, ...).
        linger_s: the emulator streams this long after the last press ends, s.
    """

    def __init__(self, presses: Sequence[Press], *, seed: int = 0, camera: SimulatedCameraConfig | None = None,
                 faults: FaultConfig | None = None, linger_s: float = 2.0) -> None:
        self.presses = list(presses)
        self.pair = SensorPair(seed=seed)
        self.camera = SimulatedCamera(camera or SimulatedCameraConfig(seed=seed), pair=self.pair)
        end = max((p.end_s for p in self.presses), default=0.0)
        self.emulator = FirmwareEmulator(EmulatorConfig(seed=seed, duration_s=end + linger_s), presses=self.presses,
                                         faults=faults, pair=self.pair)
        self.sensor: SerialSensor | None = None
        self.force: ScriptForce | None = None
        self.start_host_s = math.nan
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def open(self) -> None:
        """Solve the script for both sensors, start streaming, connect both devices on one clock."""
        self.camera.play(self.presses, start_host_s=math.inf)  # solve the camera's physics before streaming
        path = self.emulator.open()                              # solves the MBTS side
        try:
            self._thread = threading.Thread(target=self.emulator.run, args=(self._stop,), daemon=True,
                                            name="rig-emulator")
            self._thread.start()
            self.sensor = SerialSensor(SerialSensorConfig(port=path, chip=self.pair.params.chip.spec()))
            self.sensor.connect()
            self.start_host_s = self._stream_origin()
            self.camera.play(self.presses, start_host_s=self.start_host_s)
            self.camera.connect()
            self.force = ScriptForce(self.presses, self.start_host_s)
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        self.camera.disconnect()
        if self.sensor is not None:
            self.sensor.disconnect()
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self.emulator.close()

    def __enter__(self) -> SimulatedRig:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _stream_origin(self) -> float:
        """Host time of the emulator's device-clock zero: min over early frames of ``t_host - t_device``."""
        offsets = []
        with self.sensor.subscribe(max_frames=256) as sub:
            deadline = time.monotonic() + 5.0
            while len(offsets) < ORIGIN_FRAMES:
                try:
                    r = sub.get(max(0.0, deadline - time.monotonic())).reading
                except SensorTimeoutError as e:
                    raise SensorTimeoutError(f"the emulated board sent {len(offsets)} frames in 5 s: {e}") from None
                offsets.append(r.t_host_s - r.t_device_s)
        return min(offsets)
