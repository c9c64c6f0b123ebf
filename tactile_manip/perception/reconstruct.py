"""Reconstructors: a magnetic reading (R, C, 3) in, a depth image (H, W) in mm out.

- :class:`OnnxReconstructor` runs an exported SuperMag CVAE with onnxruntime (one session, explicit
  providers and threads), for one reading or a batch, with the mean and per-pixel spread of K prior samples.
- :class:`BilinearReconstructor` and :class:`BicubicReconstructor` are the paper's baselines: the z-axis 4x4
  map upsampled to the output size and mapped to millimetres by a linear fit on training data.

``load_reconstructor("bilinear" | "bicubic" | PATH)`` builds one by name. All reject NaN/inf readings and
wrong shapes with a ValueError naming the problem, and never return NaN.
"""

from __future__ import annotations

import abc
import json
import time
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage

from tactile_manip.errors import TactileManipError
from tactile_manip.extras import require

METADATA_KEY = "tactile_manip"
SUPPORTED_FORMAT = 1


class ModelFileError(TactileManipError, ValueError):
    """A model file is missing, unreadable, not ours, or does not match the readings."""


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """One reconstruction: depth (H, W) float32 mm, its spread over prior samples (or None), latency in s."""

    depth_mm: np.ndarray
    spread_mm: np.ndarray | None
    latency_s: float


class Reconstructor(abc.ABC):
    """Reading (R, C, 3) microtesla, baseline-subtracted -> depth image (H, W) in mm."""

    name: str = "reconstructor"
    input_shape: tuple[int, int, int] = (4, 4, 3)
    output_shape: tuple[int, int] = (200, 200)
    pixel_mm: float = 0.1

    def reconstruct(self, field_ut: np.ndarray) -> Reconstruction:
        """One reading -> :class:`Reconstruction`."""
        t0 = time.perf_counter()
        depth, spread = self._run(self._check(field_ut)[None])
        return Reconstruction(depth[0], None if spread is None else spread[0], time.perf_counter() - t0)

    def reconstruct_batch(self, fields_ut: np.ndarray) -> np.ndarray:
        """(N, R, C, 3) readings -> (N, H, W) float32 depth images."""
        fields = self._check(fields_ut, batch=True)
        if len(fields) == 0:
            return np.empty((0, *self.output_shape), np.float32)
        return self._run(fields)[0]

    def _check(self, field_ut: np.ndarray, *, batch: bool = False) -> np.ndarray:
        # finiteness is checked before the float32 cast: a finite float64 beyond float32's range (1e300) is a
        # huge reading, saturated to the float32 limit, not an infinite one
        f = np.asarray(field_ut, dtype=np.float64)
        want = ((None,) if batch else ()) + tuple(self.input_shape)
        if f.ndim != len(want) or any(w is not None and w != n for w, n in zip(want, f.shape)):
            shape = "(N, " + ", ".join(map(str, self.input_shape)) + ")" if batch else str(self.input_shape)
            raise ValueError(f"{self.name}: expected readings of shape {shape}, got {f.shape}")
        if not np.isfinite(f).all():
            bad = np.argwhere(~np.isfinite(f))[0].tolist()
            raise ValueError(f"{self.name}: reading contains NaN or infinite values (first at index {bad}); "
                             "drop the frame or re-read the sensor")
        f32_max = float(np.finfo(np.float32).max)
        return np.clip(f, -f32_max, f32_max).astype(np.float32)

    @abc.abstractmethod
    def _run(self, fields_ut: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """(N, R, C, 3) checked readings -> (N, H, W) depth, and spread or None."""


class OnnxReconstructor(Reconstructor):
    """An exported SuperMag model on onnxruntime.

    Args:
        path: the ``.onnx`` file written by ``tactile-manip export``.
        threads: intra-op threads (1 is the real-time setting on a CPU; 0 lets onnxruntime decide).
        providers: onnxruntime execution providers, in order of preference.
        samples: K prior samples per reading; 1 gives the deterministic prior mean (no spread).
        seed: seed of the prior samples.
    """

    def __init__(self, path: str | Path, *, threads: int = 1, providers: tuple[str, ...] = ("CPUExecutionProvider",),
                 samples: int = 1, seed: int = 0) -> None:
        ort = require("onnxruntime", "OnnxReconstructor")
        self.path = Path(path)
        if samples < 1:
            raise ValueError(f"samples must be >= 1, got {samples}")
        self.metadata = read_metadata(self.path)
        self.samples = samples
        self._rng = np.random.default_rng(seed)
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = max(0, int(threads))
        opts.inter_op_num_threads = 1
        try:
            self.session = ort.InferenceSession(str(self.path), sess_options=opts, providers=list(providers))
        except Exception as e:  # onnxruntime raises its own exception types
            raise ModelFileError(f"{self.path}: onnxruntime cannot load it: {e}") from e
        shape = self.metadata["input"]["shape"]
        self.input_shape = (int(shape[1]), int(shape[2]), int(shape[3]))
        out = self.metadata["output"]
        self.output_shape = (int(out["shape"][1]), int(out["shape"][2]))
        self.pixel_mm = float(out["pixel_mm"])
        self.latent = int(self.metadata["noise"]["shape"][2])
        self.name = f"supermag-{self.metadata.get('preset', 'model')}"

    def _run(self, fields_ut: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        n = len(fields_ut)
        if self.samples == 1:
            eps = np.zeros((n, 1, self.latent), np.float32)
        else:
            eps = self._rng.standard_normal((n, self.samples, self.latent)).astype(np.float32)
        depth, spread = self.session.run(None, {"field_ut": fields_ut, "eps": eps})
        if not (np.isfinite(depth).all() and np.isfinite(spread).all()):
            raise ModelFileError(f"{self.path}: the model produced non-finite output; the file may be corrupt")
        return depth, (spread if self.samples > 1 else None)


def read_metadata(path: str | Path) -> dict[str, Any]:
    """The ``tactile_manip`` metadata of an exported model, validated. Raises :class:`ModelFileError`."""
    path = Path(path)
    if not path.is_file():
        raise ModelFileError(f"model file not found: {path} (export one with `tactile-manip export`, or use "
                             "the shipped models/supermag_compact.onnx)")
    try:
        import onnx

        proto = onnx.load(str(path), load_external_data=False)
    except ImportError:
        return _metadata_via_ort(path)
    except Exception as e:  # onnx raises DecodeError and friends
        raise ModelFileError(f"{path}: not a readable ONNX file ({type(e).__name__}: {e})") from e
    if len(proto.graph.node) == 0:
        raise ModelFileError(f"{path}: not a readable ONNX file (empty, or no graph)")
    props = {p.key: p.value for p in proto.metadata_props}
    return _parse_metadata(path, props.get(METADATA_KEY))


def _metadata_via_ort(path: Path) -> dict[str, Any]:
    import onnxruntime as ort

    try:
        session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    except Exception as e:
        raise ModelFileError(f"{path}: not a readable ONNX file: {e}") from e
    return _parse_metadata(path, session.get_modelmeta().custom_metadata_map.get(METADATA_KEY))


def _parse_metadata(path: Path, raw: str | None) -> dict[str, Any]:
    if raw is None:
        raise ModelFileError(f"{path}: an ONNX file without tactile_manip metadata (a foreign model); export "
                             "models with `tactile-manip export`")
    try:
        meta = json.loads(raw)
    except json.JSONDecodeError as e:
        raise ModelFileError(f"{path}: tactile_manip metadata is not valid JSON: {e}") from e
    if meta.get("format_version") != SUPPORTED_FORMAT:
        raise ModelFileError(f"{path}: model format {meta.get('format_version')!r}, this code reads "
                             f"{SUPPORTED_FORMAT}")
    return meta


class InterpolationReconstructor(Reconstructor):
    """Baseline: the z-axis map upsampled to the output size, then ``depth = max(gain * b + offset, 0)``.

    The upsampling maps each output pixel centre to chip-grid coordinates (chips at pitch ``pitch_mm``,
    centred on the pad) and interpolates with a spline of ``order`` (1: bilinear, 3: bicubic), holding the
    edge values beyond the outer chips. ``gain`` (mm/uT) and ``offset`` (mm) come from :meth:`fit`.
    """

    order = 1

    def __init__(self, *, gain_mm_per_ut: float, offset_mm: float, output_shape: tuple[int, int] = (200, 200),
                 pixel_mm: float = 0.1, pitch_mm: float = 5.0, input_shape: tuple[int, int, int] = (4, 4, 3)) -> None:
        if not (np.isfinite(gain_mm_per_ut) and np.isfinite(offset_mm)):
            raise ValueError(f"{self.name}: gain and offset must be finite, got {gain_mm_per_ut}, {offset_mm}")
        self.gain, self.offset = float(gain_mm_per_ut), float(offset_mm)
        self.output_shape, self.pixel_mm, self.pitch_mm = tuple(output_shape), float(pixel_mm), float(pitch_mm)
        self.input_shape = tuple(input_shape)
        self._coords = self._grid_coords()

    def _grid_coords(self) -> np.ndarray:
        h, w = self.output_shape
        rows, cols = self.input_shape[:2]
        x = (np.arange(w) - (w - 1) / 2) * self.pixel_mm
        y = -(np.arange(h) - (h - 1) / 2) * self.pixel_mm
        col = x / self.pitch_mm + (cols - 1) / 2
        row = -y / self.pitch_mm + (rows - 1) / 2
        rr, cc = np.meshgrid(row, col, indexing="ij")
        return np.stack([rr, cc])

    def upsample(self, fields_ut: np.ndarray) -> np.ndarray:
        """(N, R, C, 3) -> (N, H, W) upsampled z-axis maps in uT."""
        return np.stack([ndimage.map_coordinates(f[..., 2].astype(np.float64), self._coords, order=self.order,
                                                 mode="nearest") for f in fields_ut])

    def _run(self, fields_ut: np.ndarray) -> tuple[np.ndarray, None]:
        depth = np.maximum(self.gain * self.upsample(fields_ut) + self.offset, 0.0)
        return depth.astype(np.float32), None

    @classmethod
    def fit(cls, fields_ut: np.ndarray, depth_mm: np.ndarray, **kwargs: Any) -> InterpolationReconstructor:
        """Least-squares ``gain`` and ``offset`` between upsampled z maps and depth images (training data)."""
        probe = cls(gain_mm_per_ut=1.0, offset_mm=0.0, output_shape=depth_mm.shape[1:], **kwargs)
        b = probe.upsample(np.asarray(fields_ut, np.float32)).ravel()
        d = np.asarray(depth_mm, np.float64).ravel()
        gain, offset = np.polyfit(b, d, 1)
        return cls(gain_mm_per_ut=float(gain), offset_mm=float(offset), output_shape=depth_mm.shape[1:], **kwargs)

    def to_dict(self) -> dict[str, Any]:
        return {"gain_mm_per_ut": self.gain, "offset_mm": self.offset, "output_shape": list(self.output_shape),
                "pixel_mm": self.pixel_mm, "pitch_mm": self.pitch_mm, "input_shape": list(self.input_shape)}


class BilinearReconstructor(InterpolationReconstructor):
    name = "bilinear"
    order = 1


class BicubicReconstructor(InterpolationReconstructor):
    name = "bicubic"
    order = 3


BASELINES: dict[str, type[InterpolationReconstructor]] = {"bilinear": BilinearReconstructor,
                                                         "bicubic": BicubicReconstructor}


def default_baseline_fit() -> dict[str, dict[str, Any]]:
    """The shipped linear fits of the baselines (on the Allen key and letter R training presses of the default
    dataset, as `tactile-manip evaluate --baseline-objects allen_key,letter_r` fits them)."""
    with resources.files("tactile_manip.data").joinpath("interpolation_fit.json").open() as f:
        return json.load(f)


def load_reconstructor(name_or_path: str | Path, **kwargs: Any) -> Reconstructor:
    """``"bilinear"`` / ``"bicubic"`` (shipped fit) or a path to an exported ``.onnx`` model.

    ``kwargs`` go to :class:`OnnxReconstructor` (threads, providers, samples, seed), or for a baseline set
    ``output_px`` (a square output of that many pixels over the same pad, e.g. 16 for the paper's 4x4 -> 16x16
    trial baseline).
    """
    key = str(name_or_path)
    if key in BASELINES:
        fit = default_baseline_fit()[key]
        fit["output_shape"] = tuple(fit["output_shape"])
        fit["input_shape"] = tuple(fit["input_shape"])
        unknown = sorted(set(kwargs) - {"output_px"})
        if unknown:
            raise ValueError(f"{key}: unknown options {unknown}; a baseline takes only output_px")
        if "output_px" in kwargs:
            size = kwargs["output_px"]
            if isinstance(size, bool) or not isinstance(size, int) or not 2 <= size <= 2000:
                raise ValueError(f"{key}: output_px must be an integer in [2, 2000], got {size!r}")
            pad_mm = fit["output_shape"][1] * fit["pixel_mm"]
            fit["output_shape"], fit["pixel_mm"] = (size, size), pad_mm / size
        return BASELINES[key](**fit)
    if not key.endswith(".onnx") and not Path(key).exists():
        raise ModelFileError(f"unknown reconstructor {key!r}: use 'bilinear', 'bicubic' or a path to an .onnx model")
    return OnnxReconstructor(key, **kwargs)
