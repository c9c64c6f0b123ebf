"""The OpenCV camera backend: a USB camera (the DTact camera, 640x480 at 30 Hz) read with ``cv2.VideoCapture``.

OpenCV is an optional extra (``pip install -e ".[camera]"``, the headless build); ``cv2`` is imported on
``connect()`` only, so importing this module, or building the camera, works without it.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from tactile_manip.extras import require
from tactile_manip.collection.camera import Camera, CameraError


def import_cv2() -> Any:
    """Return the ``cv2`` module, or raise a MissingExtraError (an ImportError) naming the extra."""
    return require("cv2", "the OpenCV camera backend")


@dataclass(frozen=True)
class OpenCVCameraConfig:
    """A USB camera through OpenCV (``cv2.VideoCapture``): the DTact camera, 640x480 at 30 Hz."""

    backend: ClassVar[str] = "opencv"
    device: int | str = 0              # camera index or device path / URL
    width_px: int = 640                # requested capture width, px
    height_px: int = 480               # requested capture height, px
    fps: float = 30.0                  # requested frame rate, Hz
    grey: bool = True                  # deliver (H, W) grey frames instead of (H, W, 3) BGR
    exposure: float | None = None      # fixed exposure (driver units); None keeps the driver's setting
    buffer_frames: int = 8             # FIFO length, frames

    def __post_init__(self) -> None:
        for name in ("width_px", "height_px", "buffer_frames"):
            v = getattr(self, name)
            if not isinstance(v, int) or v < 1:
                raise ValueError(f"OpenCVCameraConfig.{name} must be an integer >= 1, got {v!r}")
        if not (math.isfinite(self.fps) and self.fps > 0):
            raise ValueError(f"OpenCVCameraConfig.fps must be > 0, got {self.fps!r}")


class OpenCVCamera(Camera):
    """A camera read with OpenCV on a capture thread (see :class:`Camera` for the contract).

    ``t_host_s`` is ``time.monotonic()`` right after ``VideoCapture.read`` returned: the exposure was earlier
    by the camera's latency, which the collector subtracts (``CollectConfig.camera_latency_s``). ``seq`` counts
    captured frames; OpenCV does not report frames the driver dropped.
    """

    def __init__(self, config: OpenCVCameraConfig | None = None) -> None:
        self.config = config or OpenCVCameraConfig()
        super().__init__(source=f"opencv:{self.config.device}", buffer_frames=self.config.buffer_frames)
        self._cap: Any = None

    def _open(self) -> None:
        cv2 = import_cv2()
        cfg = self.config
        cap = cv2.VideoCapture(cfg.device)
        if not cap.isOpened():
            cap.release()
            raise CameraError(f"cannot open camera {cfg.device!r}: is it plugged in, and not used by another "
                              "program? (try another index, or the /dev/video* path)")
        cap.set(cv2.CAP_PROP_FRAME_WIDTH, cfg.width_px)
        cap.set(cv2.CAP_PROP_FRAME_HEIGHT, cfg.height_px)
        cap.set(cv2.CAP_PROP_FPS, cfg.fps)
        if cfg.exposure is not None:
            cap.set(cv2.CAP_PROP_AUTO_EXPOSURE, 1)  # V4L2: manual exposure, so lighting does not drift
            cap.set(cv2.CAP_PROP_EXPOSURE, cfg.exposure)
        self._cap = cap
        self._thread = threading.Thread(target=self._run, args=(cv2,), daemon=True, name="camera-opencv")
        self._thread.start()

    def _run(self, cv2: Any) -> None:
        seq = 0
        while not self._stop.is_set():
            try:
                ok, image = self._cap.read()
                t = time.monotonic()
                if not ok or image is None:
                    self._last_error = "VideoCapture.read returned no image"
                    self._stop.wait(0.05)
                    continue
                if self.config.grey and image.ndim == 3:
                    image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
                self._publish(np.ascontiguousarray(image, dtype=np.uint8), seq=seq, t_host_s=t)
                seq += 1
            except Exception as e:  # noqa: BLE001 - the thread must survive anything and report it
                self._last_error = f"{type(e).__name__} in the capture thread: {e}"
                self._stop.wait(0.05)

    def _release(self) -> None:
        if self._cap is not None:
            try:
                self._cap.release()
            except Exception:  # noqa: BLE001 - releasing a vanished device may fail; it is gone either way
                pass
            self._cap = None

    def _stale_hint(self) -> str:
        return "is the camera still plugged in and streaming?"
