"""Cameras behind one small interface: the VBTS's camera (OpenCV, optional) and its simulated twin.

A :class:`Camera` produces frames on its own thread into a short FIFO; :meth:`Camera.read` hands out the next
unread frame in order (a collector needs every frame, not just the newest), with the host time it was
captured and a sequence number that counts every frame slot, so a gap in ``seq`` is a dropped frame.

Backends are a config dataclass plus a ``"module:Class"`` entry in :data:`CAMERA_BACKENDS`, built by
:func:`make_camera` and imported only when chosen: ``OpenCVCamera`` (:mod:`tactile_manip.collection.camera_opencv`,
``pip install -e ".[camera]"``, ``cv2`` imported on ``connect()``) and ``SimulatedCamera``
(:mod:`tactile_manip.collection.camera_sim`).
"""

from __future__ import annotations

import abc
import collections
import dataclasses
import importlib
import math
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from tactile_manip.errors import SensorDisconnectedError, SensorError, SensorTimeoutError

CAMERA_BACKENDS: dict[str, str] = {
    "opencv": "tactile_manip.collection.camera_opencv:OpenCVCamera",
    "simulated": "tactile_manip.collection.camera_sim:SimulatedCamera",
}


class CameraError(SensorError):
    """A camera cannot deliver what was asked (it cannot be opened, or it returned a bad image)."""


class CameraTimeoutError(CameraError, SensorTimeoutError):
    """No new frame arrived in time; the message names the camera and what to check."""


@dataclass(frozen=True, eq=False)
class CameraFrame:
    """One camera image.

    Attributes:
        image: (H, W) grey or (H, W, 3) BGR uint8, read-only.
        t_host_s: host ``time.monotonic()`` when the frame was captured (as well as the backend knows), s.
        seq: frame slot counter from 0 after ``connect()``; a jump of more than 1 is a dropped frame.
        t_exposure_s: true exposure time on the host clock where known (the simulated camera), else NaN.
    """

    image: np.ndarray
    t_host_s: float
    seq: int
    t_exposure_s: float = math.nan


@dataclass(frozen=True)
class CameraHealth:
    """Counters since the last ``connect()``."""

    source: str
    connected: bool
    frames: int                        # frames delivered to the FIFO
    dropped: int                       # frame slots lost before delivery (gaps in seq)
    overruns: int                      # frames discarded because nobody read the FIFO in time
    rate_hz: float = math.nan          # delivered frames per second over the last second
    last_frame_age_s: float = math.inf
    last_error: str = ""


class Camera(abc.ABC):
    """A camera delivering :class:`CameraFrame` s.

    Contract, the same for every backend:

    - The constructor does no I/O. :meth:`connect` opens the device and returns once the first frame arrived;
      on failure it releases what it opened and re-raises. :meth:`disconnect` is idempotent. The camera is a
      context manager.
    - Frames are captured on a background thread into a FIFO of ``buffer_frames``; when it is full the oldest
      frame is discarded and counted in ``health().overruns``.
    - :meth:`read` returns the oldest unread frame, waiting up to ``timeout_s`` for one.
    - Reading while not connected raises :class:`SensorDisconnectedError`.
    """

    def __init__(self, *, source: str, buffer_frames: int) -> None:
        if buffer_frames < 1:
            raise ValueError(f"buffer_frames must be >= 1, got {buffer_frames}")
        self._source = source
        self._cond = threading.Condition()
        self._fifo: collections.deque[CameraFrame] = collections.deque(maxlen=buffer_frames)
        self._times: collections.deque[float] = collections.deque(maxlen=256)
        self._connected = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._reset()

    # ------------------------------------------------------------------ backend hooks

    @abc.abstractmethod
    def _open(self) -> None:
        """Open the device and start the producer thread (``self._thread``, stopping on ``self._stop``)."""

    def _release(self) -> None:
        """Release the device after the producer stopped; must not raise."""

    def _stale_hint(self) -> str:
        return "is the camera still streaming?"

    # ------------------------------------------------------------------ lifecycle

    @property
    def source(self) -> str:
        return self._source

    @property
    def is_connected(self) -> bool:
        return self._connected

    def connect(self, timeout_s: float = 5.0) -> None:
        """Open the camera and wait up to ``timeout_s`` for the first frame.

        Raises:
            CameraError: already connected, or the device cannot be opened.
            CameraTimeoutError: it opened but no frame came.
        """
        if self._connected:
            raise CameraError(f"camera {self._source} is already connected; call disconnect() first")
        with self._cond:
            self._fifo.clear()
            self._times.clear()
            self._reset()
        self._stop.clear()
        self._connected = True
        try:
            self._open()
            with self._cond:
                if not self._cond.wait_for(lambda: self._frames > 0, timeout=timeout_s):
                    raise CameraTimeoutError(self._stale(f"no frame within {timeout_s:.1f} s of opening"))
        except BaseException:
            self.disconnect()
            raise

    def disconnect(self) -> None:
        """Stop capturing and release the device; a no-op when not connected."""
        if not self._connected:
            return
        self._connected = False
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        self._release()
        with self._cond:
            self._cond.notify_all()

    def __enter__(self) -> Camera:
        self.connect()
        return self

    def __exit__(self, *exc: object) -> None:
        self.disconnect()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self._source!r}, {'connected' if self._connected else 'disconnected'})"

    # ------------------------------------------------------------------ frames

    def read(self, timeout_s: float = 1.0) -> CameraFrame:
        """The oldest unread frame, waiting up to ``timeout_s`` seconds for one.

        Raises:
            CameraTimeoutError: no frame within ``timeout_s`` (the camera stopped or is too slow).
            SensorDisconnectedError: not connected, or disconnected while waiting.
        """
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while True:
                self._require_connected()
                if self._fifo:
                    return self._fifo.popleft()
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    break
                self._cond.wait(remaining)
        raise CameraTimeoutError(self._stale(f"no new frame within {timeout_s:.2f} s"))

    def drain(self) -> list[CameraFrame]:
        """Every unread frame now, oldest first, without waiting."""
        self._require_connected()
        with self._cond:
            out = list(self._fifo)
            self._fifo.clear()
        return out

    def health(self) -> CameraHealth:
        now = time.monotonic()
        with self._cond:
            times = list(self._times)
            recent = [t for t in times if times and times[-1] - t <= 1.0]
            rate = (len(recent) - 1) / (recent[-1] - recent[0]) if len(recent) > 2 and recent[-1] > recent[0] \
                else math.nan
            return CameraHealth(source=self._source, connected=self._connected, frames=self._frames,
                                dropped=self._dropped, overruns=self._overruns, rate_hz=rate,
                                last_frame_age_s=now - times[-1] if times else math.inf, last_error=self._last_error)

    # ------------------------------------------------------------------ for backends

    def _publish(self, image: np.ndarray, *, seq: int, t_host_s: float, t_exposure_s: float = math.nan) -> None:
        """Hand a captured image to readers (producer thread); ``seq`` counts every slot, dropped ones too."""
        image.flags.writeable = False
        frame = CameraFrame(image=image, t_host_s=t_host_s, seq=seq, t_exposure_s=t_exposure_s)
        with self._cond:
            if self._last_seq is not None and seq > self._last_seq + 1:
                self._dropped += seq - self._last_seq - 1
            self._last_seq = seq
            if len(self._fifo) == self._fifo.maxlen:
                self._overruns += 1
            self._fifo.append(frame)
            self._times.append(t_host_s)
            self._frames += 1
            self._cond.notify_all()

    def _stale(self, what: str) -> str:
        err = f" (last error: {self._last_error})" if self._last_error else ""
        return f"{what} from camera {self._source}: {self._stale_hint()}{err}"

    def _require_connected(self) -> None:
        if not self._connected:
            raise SensorDisconnectedError(f"camera {self._source} is not connected: call connect() first "
                                          "(or use it as a context manager)")

    def _reset(self) -> None:
        self._frames = self._dropped = self._overruns = 0
        self._last_seq: int | None = None
        self._last_error = ""


def make_camera(config: Any, **kwargs: Any) -> Camera:
    """Build (not connect) the camera backend named by ``config.backend``."""
    name = getattr(config, "backend", None)
    if not dataclasses.is_dataclass(config) or name not in CAMERA_BACKENDS:
        raise ValueError(f"config must be a camera config ({', '.join(CAMERA_BACKENDS)}), got {type(config).__name__}")
    module, _, cls = CAMERA_BACKENDS[name].partition(":")
    return getattr(importlib.import_module(module), cls)(config, **kwargs)
