"""Where the press force comes from, and the trigger that turns it into "take this camera frame".

SuperMag's gripper closes until the press force reaches a threshold (10 N, Sec. III-D); the recorder takes its
pairs there. A :class:`ForceSource` gives the force by host time: the gripper's own reading
(:class:`FunctionForce`), a proxy from the MBTS reading for rigs without one (:class:`FieldForce`), or the
press script in simulation (:class:`ScriptForce`, which also labels each press with its object and pose).
:class:`PressTrigger` decides which camera frames of a press to take.
"""

from __future__ import annotations

import abc
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from tactile_manip.checks import check_finite_scalar
from tactile_manip.sensors.base import TactileSensor
from tactile_manip.sensors.simulated.contacts import Press


@dataclass(frozen=True)
class PressLabel:
    """What is being pressed: the object's name and, where known (simulation), its pose on the MBTS pad."""

    object_name: str
    pose: tuple[float, float, float, float, float] | None = None  # x_mm, y_mm, yaw_rad, tilt_x_rad, tilt_y_rad


class ForceSource(abc.ABC):
    """The rig's press force (the gripper's), by host time."""

    @abc.abstractmethod
    def force_n(self, t_host_s: float) -> float:
        """Press force at host time ``t_host_s`` (``time.monotonic()``), N; a live source may return its latest."""

    def label(self, t_host_s: float) -> PressLabel | None:
        """The object pressed at ``t_host_s`` where the source knows it (None: the collector's object name)."""
        return None

    def finished(self, t_host_s: float) -> bool:
        """True once no further press will come (a finite script); live sources never finish."""
        return False


class FunctionForce(ForceSource):
    """A force read from a function, e.g. ``FunctionForce(lambda: gripper.state().force_n)``."""

    def __init__(self, read_force_n: Callable[[], float]) -> None:
        self._read = read_force_n

    def force_n(self, t_host_s: float) -> float:
        return float(self._read())


class FieldForce(ForceSource):
    """A force proxy from the MBTS itself, for rigs without a force reading: ``|field_ut| / ut_per_n``.

    The norm of the baseline-subtracted 4x4x3 reading grows with the press force (~50-85 uT per newton at
    10 N in the simulator, object dependent); set ``ut_per_n`` from one press at a known force. Uses the
    buffered reading nearest to the asked time.
    """

    def __init__(self, sensor: TactileSensor, ut_per_n: float = 60.0) -> None:
        self.sensor = sensor
        self.ut_per_n = check_finite_scalar("ut_per_n", ut_per_n, low=0.0, low_open=True)

    def force_n(self, t_host_s: float) -> float:
        """The proxy at the buffered reading nearest ``t_host_s``; 0 until the sensor has a baseline."""
        window = self.sensor.window(32)
        if not window or self.sensor.baseline is None:
            return 0.0
        r = min(window, key=lambda w: abs(w.t_host_s - t_host_s))
        return float(np.linalg.norm(r.field_ut)) / self.ut_per_n


class ScriptForce(ForceSource):
    """The force of a press script played from host time ``start_host_s`` (the simulated gripper)."""

    def __init__(self, presses: Sequence[Press], start_host_s: float) -> None:
        self.presses = tuple(sorted(presses, key=lambda p: p.start_s))
        self.start_host_s = float(start_host_s)

    def _active(self, t_host_s: float) -> Press | None:
        t = t_host_s - self.start_host_s
        for p in self.presses:
            if p.start_s < t < p.end_s:
                return p
        return None

    def force_n(self, t_host_s: float) -> float:
        p = self._active(t_host_s)
        return 0.0 if p is None else p.force_at(t_host_s - self.start_host_s)

    def label(self, t_host_s: float) -> PressLabel | None:
        p = self._active(t_host_s)
        if p is None:
            return None
        q = p.pose
        return PressLabel(p.name, (q.x_mm, q.y_mm, q.yaw_rad, q.tilt_x_rad, q.tilt_y_rad))

    @property
    def end_host_s(self) -> float:
        return self.start_host_s + (self.presses[-1].end_s if self.presses else 0.0)

    def finished(self, t_host_s: float) -> bool:
        return t_host_s > self.end_host_s


class PressTrigger:
    """Which camera frames to take: ``pairs_per_press`` at or above ``threshold_n`` per press, re-armed below
    ``release_n``, starting ``settle_s`` after the threshold was first reached."""

    def __init__(self, threshold_n: float, release_n: float, pairs_per_press: int, settle_s: float = 0.0) -> None:
        self.threshold_n, self.release_n = threshold_n, release_n
        self.pairs_per_press, self.settle_s = pairs_per_press, settle_s
        self.presses = 0           # presses that reached the threshold
        self.complete = 0          # presses that got all their pairs
        self._armed = True
        self._t_trigger = math.nan
        self._asked = self._got = 0

    def want(self, t_s: float, force_n: float) -> int | None:
        """The press index if the frame at ``t_s`` with ``force_n`` should be taken, else None."""
        if force_n < self.release_n:
            self._armed = True
            return None
        if self._armed and force_n >= self.threshold_n:
            self._armed = False
            self.presses += 1
            self._t_trigger, self._asked, self._got = t_s, 0, 0
        if (not self._armed and self.presses and force_n >= self.threshold_n and t_s >= self._t_trigger + self.settle_s
                and self._asked < self.pairs_per_press):
            self._asked += 1
            return self.presses - 1
        return None

    def result(self, press: int, paired: bool) -> None:
        """Feedback for a taken frame: a failed pair frees its slot while its press lasts."""
        if press != self.presses - 1:
            return
        if paired:
            self._got += 1
            if self._got == self.pairs_per_press:
                self.complete += 1
        else:
            self._asked -= 1
