"""The trial cell on a real robot: FR3 and Franka Hand through franky, the board on a serial port, an operator.

The same scene file and the same behaviour as in simulation; what the simulator did, a person does:

1. present: the operator holds the object between the open fingers at the drawn in-hand angle and offset
   (printed in the pad frame) and confirms; the gripper then closes on it;
2. measure: after the correction the operator measures the object's angle in the pad plane of the grasp
   (protractor or camera) and types it; a blank answer records the trial as done with an unknown error,
   which the summary then counts as a failure.

Both prompts go through ``ask`` / ``say`` callables (``input`` and ``print`` by default) so a GUI or a
tracker can answer instead. The arm is wrapped in :class:`~tactile_manip.robot.safety.SafeArm` and moves at
the scene's low ``relative_dynamics_factor``; faults are recovered at the trial boundary.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from tactile_manip.errors import ConfigError
from tactile_manip.extras import require
from tactile_manip.robot.base import Arm, Gripper
from tactile_manip.robot.frames import hand_T_pad
from tactile_manip.sensors.base import TactileSensor
from tactile_manip.sensors.config import SerialSensorConfig
from tactile_manip.trials.cells import make_task, trial_of
from tactile_manip.trials.scene import TrialScene

if TYPE_CHECKING:
    from tactile_manip.perception.tactile_estimator import TactileEstimator


@dataclass(frozen=True)
class PresentedObject:
    """What the behaviour needs of the object on a real robot: its label and nominal width."""

    name: str
    width_m: float


class OperatorTruth:
    """The operator's measurement of the final angle, turned into an axis in the base frame."""

    def __init__(self, base_T_pad: np.ndarray, ask: Callable[[str], str], say: Callable[[str], None]) -> None:
        self._base_T_pad, self._ask, self._say = base_T_pad, ask, say

    def object_axis_base(self) -> np.ndarray | None:
        prompt = "measured final angle of the object's axis in the grasp's pad plane, deg (blank: unknown): "
        while True:
            answer = self._ask(prompt).strip()
            if not answer:
                return None
            try:
                angle = math.radians(float(answer))
            except ValueError:
                self._say(f"not a number: {answer!r}")
                continue
            if math.isfinite(angle):
                return self._base_T_pad[:3, :3] @ np.array([math.cos(angle), math.sin(angle), 0.0])
            self._say(f"not a finite angle: {answer!r}")


class OperatorCell:
    """A real cell (see the module docstring). ``arm``/``gripper``/``sensor`` default to the scene's franky
    backend and serial sensor; pass your own (e.g. franky-sim, or any Arm) to override.

    Building one opens nothing, but fails where connecting would fail for certain, so `tactile-manip trials`
    stops before it writes its run folder: SensorDisconnectedError when the scene's board is not plugged in
    (no such port, or no port with its serial number), MissingExtraError without pyserial or franky.
    """

    def __init__(self, scene: TrialScene, *, arm: Arm | None = None, gripper: Gripper | None = None,
                 sensor: TactileSensor | None = None, ask: Callable[[str], str] = input,
                 say: Callable[[str], None] = print) -> None:
        if scene.faults.arm_fault_trials or scene.faults.sensor_stall_trials:
            raise ConfigError("faults: injected faults exist only in simulation (robot.backend = 'twin')")
        if sensor is None and not isinstance(scene.sensor, SerialSensorConfig):
            raise ConfigError("sensor: a real robot needs the real board: give [sensor] a port "
                              "(e.g. port = \"/dev/ttyUSB0\")")
        self.scene, self._ask, self._say = scene, ask, say
        self.task = make_task(scene)
        # what can be known to fail is checked here, before `tactile-manip trials` writes its run folder
        if sensor is None:
            from tactile_manip.sensors.serial_sensor import SerialSensor

            sensor = SerialSensor(scene.sensor)
            sensor.check_port()
        if arm is None or gripper is None:
            from tactile_manip.robot.franky_arm import FrankyArm, FrankyConfig, FrankyGripper
            from tactile_manip.robot.safety import SafeArm

            require("franky", "the real FR3 (robot.backend = 'franky')")
            config = FrankyConfig(host=scene.robot.host, relative_dynamics_factor=scene.robot.relative_dynamics_factor,
                                  home_q_rad=scene.robot.home_q_rad, enforce_realtime=scene.robot.enforce_realtime)
            arm = arm or SafeArm(FrankyArm(config), scene.robot.safety)
            gripper = gripper or FrankyGripper(config)
        self.arm, self.gripper, self.sensor = arm, gripper, sensor

    @contextlib.contextmanager
    def connected(self) -> Iterator[OperatorCell]:
        """Connect everything, home, open, and take the sensor's baseline with the pad clear."""
        with self.sensor, self.arm, self.gripper:
            self.arm.recover()
            self.arm.home()
            self.gripper.open()
            self._ask("clear the tactile pad (nothing touching it), then press Enter to take its baseline ")
            self.sensor.calibrate_baseline()
            yield self

    @contextlib.contextmanager
    def presented(self, p) -> Iterator[tuple[PresentedObject, OperatorTruth]]:
        """Trial boundary (recover, home, open), then the operator presents ``p``'s object."""
        self.arm.recover()
        self.arm.home()
        self.gripper.open()
        obj = PresentedObject(p.obj.display_name, p.obj.grasp_width_m)
        self._say(f"trial {p.trial}: hold {obj.name} ({obj.width_m * 1e3:.1f} mm) between the fingers, its axis at "
                  f"{math.degrees(p.angle_rad):+.1f} deg from the pad's x axis (hand x), centred "
                  f"({p.offset_mm[0]:+.1f}, {p.offset_mm[1]:+.1f}) mm from the pad centre")
        self._ask("press Enter when it is in place ")
        base_T_pad = self.arm.state().base_T_hand @ hand_T_pad()
        try:
            yield obj, OperatorTruth(base_T_pad, self._ask, self._say)
        finally:
            self.gripper.open()
            self._ask("take the object out of the hand, then press Enter ")

    def run_one(self, p, estimator: TactileEstimator, *, arm_fault: bool = False, sensor_stall: bool = False,
                observer=None):
        """Present ``p``, run the scene's task, ask for the measured final angle (``estimator`` and
        ``observer``: see :meth:`~tactile_manip.trials.cells.SimulatedCell.run_one`)."""
        if arm_fault or sensor_stall:
            raise ConfigError("injected faults exist only in simulation")
        with self.presented(p) as (obj, truth):
            return self.task.run(trial_of(self, p, estimator, obj.width_m, truth, observer))
