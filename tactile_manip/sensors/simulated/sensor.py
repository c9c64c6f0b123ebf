"""The simulated backend: readings produced in process from the paired-sensor simulator, no bytes involved.

A frame thread ticks at the chip rate on a monotonic schedule. Each tick takes the current noise-free field
(baseline plus the contact's change, solved once per contact and cached) and draws fresh chip noise with
``ChipArray.measure``, so a frame costs ~50 us while a press costs ~30-100 ms. A behaviour puts the true
contact on the sensor with :meth:`SimulatedSensor.set_contact`; a scripted ramp plays with
:meth:`SimulatedSensor.play`; :meth:`SimulatedSensor.stall` makes it go stale like a hung board.
"""

from __future__ import annotations

import collections
import dataclasses
import threading
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from tactile_manip.boards import load_board
from tactile_manip.checks import check_finite_scalar
from tactile_manip.sensors.base import TactileSensor
from tactile_manip.sensors.config import SimulatedSensorConfig
from tactile_manip.sensors.simulated.contacts import ContactTimeline, Press
from tactile_manip.sim.objects import Indenter, IndenterPose
from tactile_manip.sim.pair import SensorPair

CACHE_SIZE = 64       # solved contacts kept (indenter, pose, force)
REBASE_LATE_S = 0.25  # a tick this late restarts the schedule instead of bursting to catch up


class SimulatedSensor(TactileSensor):
    """The simulated MBTS (see :class:`~tactile_manip.sensors.base.TactileSensor` for the contract).

    Deterministic for a seed: frame ``k`` after ``connect()`` carries the ``k``-th noise draw (stalled ticks
    draw nothing); which frame a contact first appears in depends on when it was set.

    Readings have the pair's board's shape (``layout`` is that board).

    Args:
        config: board, seed, frame rate, buffer length, baseline settings.
        pair: the simulated sensor pair to read (shared with a behaviour so both see the same physics);
            default ``SensorPair(board=load_board(config.board), seed=config.seed)``.
    """

    def __init__(self, config: SimulatedSensorConfig | None = None, *, pair: SensorPair | None = None) -> None:
        config = config or SimulatedSensorConfig()
        self.config = config
        self.pair = pair if pair is not None else SensorPair(board=load_board(config.board), seed=config.seed)
        chip = dataclasses.replace(self.pair.params.chip, rate_hz=config.rate_hz)
        super().__init__(source="simulated", chip=chip, buffer_frames=config.buffer_frames, baseline=config.baseline,
                         layout=self.pair.board)
        self._cache: collections.OrderedDict[tuple, np.ndarray] = collections.OrderedDict()
        self._static: np.ndarray | None = None
        self._script: tuple[ContactTimeline, float] | None = None
        self._stalled = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._cpu_s = 0.0
        self._last_error = ""
        self._pair_generation = self._published_generation = 0  # replace_pair count; that of the last frame out
        # held while a frame is measured and published, and while the contact changes: a frame published after
        # set_contact, clear_contact or play returns carries the new contact
        self._contact_lock = threading.Lock()

    # ------------------------------------------------------------------ contacts and faults

    def set_contact(self, indenter: Indenter, pose: IndenterPose, force_n: float) -> np.ndarray:
        """Press ``indenter`` at ``pose`` with ``force_n`` from the next frame on (replaces any script).

        The first call for a contact solves it (~30-100 ms, in the caller's thread); repeats come from a cache.

        Returns:
            (rows, cols, 3) float64 noise-free field change in uT, pad axes (the ground truth of the reading).

        Raises:
            ValueError: a negative or non-finite force.
            SimulationError: the force pushes the object through the layer (it would bottom out).
        """
        force = check_finite_scalar("force_n", force_n, low=0.0)
        key = (indenter, pose, force)
        change = self._cache.get(key)  # (n_chips, 3), firmware order
        if change is None:
            change = np.zeros((self.pair.board.n_chips, 3))
            if force > 0:
                rng = np.random.default_rng(self.config.seed)  # the press's own noise is not used
                sample = self.pair.press(indenter, pose, force, rng, render_depth=False).check_within_layer()
                change = self.pair.board.chips_from_cells(sample.field_change_ut).astype(np.float64)
            self._cache[key] = change
            if len(self._cache) > CACHE_SIZE:
                self._cache.popitem(last=False)
        else:
            self._cache.move_to_end(key)
        with self._contact_lock:
            self._script = None
            self._static = change
        return self.pair.to_reading(change)

    def replace_pair(self, pair: SensorPair) -> None:
        """Read another simulated sensor pair from the next frame on (say, a drawn skin per trial).

        Its no-contact field differs from the old one's: take a new baseline (pad unloaded) before reading
        contacts. Its chips are rated by their own noise (the baseline's refusal threshold follows them). The
        contact in place is cleared; cached contact solves belong to the old pair and are dropped.

        Raises:
            ValueError: a pair of another board (readings would change shape under the readers).
        """
        if pair.board is not self.pair.board and pair.board.name != self.pair.board.name:
            raise ValueError(f"replace_pair: the sensor reads board {self.pair.board.name}, the pair is "
                             f"{pair.board.name}'s")
        self.clear_contact()
        self._cache.clear()
        self._chip = dataclasses.replace(pair.params.chip, rate_hz=self.config.rate_hz)
        self.pair = pair
        self._pair_generation += 1
        # a frame measured on the old pair may still be in flight: return once one of the new pair is out, so
        # that a baseline taken next averages the new sensor only
        if self._thread is not None and self._thread.is_alive() and not self._stalled:
            with self._cond:
                self._cond.wait_for(lambda: self._published_generation == self._pair_generation, timeout=1.0)

    def clear_contact(self) -> None:
        """Nothing on the pad from the next frame on (stops a script too): no frame published after this returns
        carries the contact."""
        with self._contact_lock:
            self._script = None
            self._static = None

    def play(self, presses: Sequence[Press], *, period_s: float | None = None) -> ContactTimeline:
        """Solve a script of presses (in the caller's thread), then play it from now; replaces any contact."""
        timeline = ContactTimeline(self.pair, presses, period_s=period_s, seed=self.config.seed)
        with self._contact_lock:
            self._static = None
            self._script = (timeline, time.monotonic())
        return timeline

    @property
    def contact_field_ut(self) -> np.ndarray:
        """The noise-free field change (rows, cols, 3) in uT (pad axes) that the next frame will carry."""
        return self.pair.to_reading(self._change_at(time.monotonic()))

    @property
    def expected_baseline_ut(self) -> np.ndarray:
        """(rows, cols, 3) float32 idle reading without noise, uT: pass it to ``set_baseline`` to skip
        calibration."""
        return self.pair.baseline_reading_ut.astype(np.float32)

    def stall(self) -> None:
        """Stop producing frames (like a hung board) until :meth:`resume`; readers go stale."""
        self._stalled = True

    def resume(self) -> None:
        """Produce frames again after :meth:`stall` (the frame counter continues without a gap)."""
        self._stalled = False

    @property
    def stalled(self) -> bool:
        return self._stalled

    # ------------------------------------------------------------------ TactileSensor hooks

    def _open(self) -> None:
        self._stop.clear()
        self._cpu_s, self._last_error = 0.0, ""
        self._start_session()
        self._thread = threading.Thread(target=self._run, daemon=True, name="tactile-simulated")
        self._thread.start()
        with self._cond:  # a stalled sensor connects without a frame, like a hung board that enumerates
            self._cond.wait_for(lambda: self._frames > 0 or self._stalled, timeout=2.0)

    def _close(self) -> None:
        self._stop_producer()

    def _link_health(self) -> dict[str, Any]:
        return {"link_up": self._connected and not self._stalled, "reader_cpu_s": self._cpu_s,
                "last_error": self._last_error}

    def _stale_hint(self) -> str:
        if self._stalled:
            return "the simulated sensor is stalled: call resume()"
        return "the simulated frame thread is not keeping up (is the machine overloaded?)"

    # ------------------------------------------------------------------ the frame thread

    def _change_at(self, t_host_s: float) -> np.ndarray:
        static, script = self._static, self._script
        if static is not None:
            return static
        if script is not None:
            timeline, t0 = script
            return timeline.chip_change_at(t_host_s - t0)
        return np.zeros((self.pair.board.n_chips, 3))

    def _run(self) -> None:
        cpu0 = time.thread_time()
        rng = np.random.default_rng(self.config.seed)
        period = 1.0 / self.config.rate_hz
        t0, k, seq = time.monotonic(), 0, 0
        while True:
            deadline = t0 + k * period
            wait = deadline - time.monotonic()
            if self._stop.wait(wait) if wait > 0 else self._stop.is_set():
                break
            try:
                if wait < -REBASE_LATE_S:
                    t0 = time.monotonic() - k * period
                if not self._stalled:
                    # read per frame (generation first): replace_pair swaps the pair while the thread runs
                    generation, pair = self._pair_generation, self.pair
                    with self._contact_lock:
                        m = pair.chips.measure(pair.baseline_field_ut + self._change_at(deadline), rng)
                        self._publish(pair.to_reading(m.raw_ut), pair.to_reading(m.saturated), seq=seq,
                                      t_host_s=time.monotonic(), t_device_s=k * period)
                    with self._cond:
                        self._published_generation = generation
                        self._cond.notify_all()
                    seq += 1
            except Exception as e:  # noqa: BLE001 - the thread must survive anything and report it
                self._last_error = f"{type(e).__name__} in the frame thread: {e}"
            finally:
                k += 1
                self._cpu_s = time.thread_time() - cpu0
