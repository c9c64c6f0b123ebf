"""Reconstructors: a magnetic reading (R, C, 3) in, a depth image (H, W) in mm out.

- :class:`OnnxReconstructor` runs an exported SuperMag CVAE with onnxruntime (one session, explicit
  providers and threads), for one reading or a batch, with the mean and per-pixel spread of K prior samples.
- :class:`BilinearReconstructor` and :class:`BicubicReconstructor` are the paper's baselines: the z-axis 4x4
  map upsampled to the output size and mapped to millimetres by a linear fit on training data.

``load_reconstructor("bilinear" | "bicubic" | PATH)`` builds one by name. All reject NaN/inf readings and
wrong shapes with a ValueError naming the problem, and never return NaN. All clamp a reading to the chip's
range first (:data:`READING_LIMIT_UT`, see :func:`out_of_range`), so a value no MLX90393 can report (3e38 from
a corrupt buffer) enters every reconstructor as the same bound; the estimator flags such channels and lowers
the confidence.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import abc
import json
import math
import time
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage

from tactile_manip.boards.identity import check_board_of, check_model_of_current_board
from tactile_manip.chips import MLX90393, full_scale_ut
from tactile_manip.perception.angle_head import AngleHead, open_angle_head
from tactile_manip.perception.board_symmetry import average_images, image_subgroup
from tactile_manip.perception.model_metadata import ModelFileError, check_metadata
from tactile_manip.perception.one_reading import open_one_reading
from tactile_manip.perception.onnx_session import session_options
from tactile_manip.extras import require
from tactile_manip.shipped import SHIPPED_MODELS, missing_model_message, resolve_model_path

if TYPE_CHECKING:
    from tactile_manip.boards.board import Board

METADATA_KEY = "tactile_manip"
SYMMETRY_CHUNK = 64  # readings per batch of symmetric copies (4 or 8 images each)
SUPPORTED_FORMAT = 1
# (3,) uT: the MLX90393's full scale per axis (x, y, z) at ReSkin's settings; no reading can exceed it
READING_LIMIT_UT = full_scale_ut(MLX90393)


def out_of_range(field_ut: np.ndarray) -> np.ndarray:
    """Channels beyond the chip's full scale: bool array of ``field_ut``'s shape (..., 3), uT in.

    Such a value did not come from a magnetometer (a corrupt buffer, a unit mix-up); every reconstructor
    clamps it to :data:`READING_LIMIT_UT`, and :class:`~tactile_manip.perception.TactilePoseEstimator` counts
    its chip as saturated. NaN is not flagged here (the reconstructors refuse it).
    """
    f = np.asarray(field_ut, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.abs(f) > _limit_for(f.shape)


def _limit_for(shape: tuple[int, ...]) -> np.ndarray | float:
    """The per-axis limit for readings of ``shape`` (the largest one when the last axis is not x, y, z)."""
    return READING_LIMIT_UT if shape and shape[-1] == 3 else float(READING_LIMIT_UT.max())
DEFAULT_BOARD_LAYOUT = "supermag-4x4"  # the board every shipped model was trained on (tactile_manip/boards)


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """One reconstruction: depth (H, W) float32 mm, its spread over prior samples (or None), latency in s."""

    depth_mm: np.ndarray
    spread_mm: np.ndarray | None
    latency_s: float


class Reconstructor(abc.ABC):
    """Reading (R, C, 3) microtesla, baseline-subtracted -> depth image (H, W) in mm.

    ``board_layout`` names the sensor board (``tactile_manip.boards``) whose readings it was made for;
    :meth:`check_layout` refuses readings of another board. ``angle_head`` is the model file's angle head
    (:class:`~tactile_manip.perception.angle_head.AngleHead`: the contact's axis straight from the reading,
    from which the pose estimator takes the angle by default), or None.
    """

    name: str = "reconstructor"
    angle_head: AngleHead | None = None
    #: whether a reading's image is always the same (False where prior samples are drawn per call)
    deterministic: bool = True
    board_layout: str = DEFAULT_BOARD_LAYOUT
    input_shape: tuple[int, int, int] = (4, 4, 3)
    output_shape: tuple[int, int] = (200, 200)
    pixel_mm: float = 0.1

    def reconstruct(self, field_ut: np.ndarray) -> Reconstruction:
        """One reading -> :class:`Reconstruction`."""
        t0 = time.perf_counter()
        depth, spread = self._run(self._check(field_ut)[None])
        return Reconstruction(depth[0], None if spread is None else spread[0], time.perf_counter() - t0)

    def checked(self, field_ut: np.ndarray) -> np.ndarray:
        """One reading (R, C, 3) as the model reads it: float32, clamped to the chip's range; refuses wrong
        shapes and NaN / infinite values (ValueError)."""
        return self._check(field_ut)

    def checked_many(self, fields_ut: np.ndarray) -> np.ndarray:
        """Readings (N, R, C, 3) as the model reads them (see :meth:`checked`)."""
        return self._check(fields_ut, batch=True)

    def check_layout(self, layout: str | Board) -> None:
        """Refuse readings of board layout ``layout`` (a name, or a sensor's :class:`~tactile_manip.boards.Board`,
        told apart by what its readings depend on) unless it is the one this reconstructor was made for."""
        if check_board_of(self.name, getattr(self, "metadata", {"board_layout": self.board_layout}), layout):
            return
        if getattr(layout, "name", layout) != self.board_layout:
            raise ValueError(f"{self.name} takes readings of the {self.board_layout!r} board layout, but the sensor "
                             f"has the {layout!r} layout: train or export a model for that board")

    def reconstruct_many(self, fields_ut: np.ndarray) -> list[Reconstruction]:
        """(N, R, C, 3) readings -> N :class:`Reconstruction` from one batched run (spread included), each
        with the batch's latency."""
        t0 = time.perf_counter()
        fields = self._check(fields_ut, batch=True)
        if len(fields) == 0:
            return []
        depth, spread = self._run(fields)
        latency = time.perf_counter() - t0
        return [Reconstruction(depth[i], None if spread is None else spread[i], latency) for i in range(len(depth))]

    def reconstruct_batch(self, fields_ut: np.ndarray) -> np.ndarray:
        """(N, R, C, 3) readings -> (N, H, W) float32 depth images."""
        fields = self._check(fields_ut, batch=True)
        if len(fields) == 0:
            return np.empty((0, *self.output_shape), np.float32)
        return self._run(fields)[0]

    #: readings are MLX90393 fields in uT (clamped to the chip's full scale); False for models trained on
    #: another sensor's readings (tactile-manip import), whose values pass as they are
    magnetic_ut: bool = True
    #: the symmetries of the board each image is averaged over (:data:`~.board_symmetry.IMAGE_SYMMETRIES`)
    image_symmetry: str = "none"

    def _check(self, field_ut: np.ndarray, *, batch: bool = False) -> np.ndarray:
        # finiteness is checked before the float32 cast and the clamp: a finite float64 beyond float32's range
        # (1e300) is a huge reading, clamped to the chip's range like 3e38 or 1e6, not an infinite one
        f = np.asarray(field_ut, dtype=np.float64)
        want = ((None,) if batch else ()) + tuple(self.input_shape)
        if f.ndim != len(want) or any(w is not None and w != n for w, n in zip(want, f.shape)):
            shape = "(N, " + ", ".join(map(str, self.input_shape)) + ")" if batch else str(self.input_shape)
            raise ValueError(f"{self.name}: expected readings of shape {shape}, got {f.shape} (it takes readings "
                             f"of the {self.board_layout} board layout)")
        if not np.isfinite(f).all():
            bad = np.argwhere(~np.isfinite(f))[0].tolist()
            raise ValueError(f"{self.name}: reading contains NaN or infinite values (first at index {bad}); "
                             "drop the frame or re-read the sensor")
        if not self.magnetic_ut:  # another sensor's readings (pF, counts): the MLX90393's range means nothing
            return f.astype(np.float32)
        limit = _limit_for(f.shape)
        return np.clip(f, -limit, limit).astype(np.float32)

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
        one_reading_graph: with one sample and one thread, run single readings through the file's one-reading
            graph (:mod:`~tactile_manip.perception.one_reading`; 10 % less network time, the same images) when
            it has one; False always runs the main graph. :attr:`one_reading` says whether it is used. With
            more threads the main graph runs alone: each onnxruntime session spins its own thread pool, and two
            sessions taking turns fight over the cores (p99 5 ms against 1.1 ms at 2 threads on 2 cores).
        angle_head: open the file's angle head when it has one (:attr:`angle_head`); False leaves it out (the
            pose estimator then reads the angle from the image alone).
        image_symmetry: what each image is averaged over: ``"none"`` (the default) decodes the reading once
            (the default model: p99 within 2.5 ms on one thread); ``"rotations"`` decodes it in its 4 quarter
            turns and averages the turned-back images (exactly equivariant under the turns, sharper on unseen
            shapes: +0.41 dB PSNR for the default model's decoder on the unseen presses of
            ``data/supermag.npz``, 25.16 against 24.75 dB), ``"all"`` in its 8 symmetric copies; ``"stored"``
            takes what the file says (``"none"`` for files that say nothing; ``models/supermag.onnx`` says
            ``"rotations"``: its published image figures are of that average). Each copy is a decoder pass: 4 or
            8 times the image's cost, which only callers of the image pay (the angle head reads the reading).
            ``benchmarks/bench_depth.py`` measures each choice.
    """

    def __init__(self, path: str | Path, *, threads: int = 1, providers: tuple[str, ...] = ("CPUExecutionProvider",),
                 samples: int = 1, seed: int = 0, one_reading_graph: bool = True, angle_head: bool = True,
                 image_symmetry: str = "none") -> None:
        ort = require("onnxruntime", "OnnxReconstructor")
        self.path = resolve_model_path(path)  # a shipped model's name, or a checkout's path from any folder
        if samples < 1:
            raise ValueError(f"samples must be >= 1, got {samples}")
        self.metadata = read_metadata(self.path)
        if self.metadata.get("kind", "image") != "image":
            raise ModelFileError(f"{self.path}: a {self.metadata['kind']} model, not an image model: load it with "
                                 "tactile_manip.perception.contact.ContactEstimator (evaluate takes either)")
        check_model_of_current_board(str(self.path), self.metadata, recipe_of(self.path))
        self.samples = samples
        self.deterministic = samples == 1
        self._rng = np.random.default_rng(seed)
        options = session_options(ort, threads=threads)
        try:
            self.session = ort.InferenceSession(str(self.path), sess_options=options, providers=list(providers))
        except Exception as e:  # onnxruntime raises its own exception types
            raise ModelFileError(f"{self.path}: onnxruntime cannot load it: {e}") from e
        check_metadata(self.metadata, self.session, path=self.path)  # types, shapes, board layout
        shape = self.metadata["input"]["shape"]
        self.input_shape = (int(shape[1]), int(shape[2]), int(shape[3]))
        out = self.metadata["output"]
        self.output_shape = (int(out["shape"][1]), int(out["shape"][2]))
        self.pixel_mm = float(out["pixel_mm"])
        self.latent = int(self.metadata["noise"]["shape"][2])
        self.name = f"supermag-{self.metadata.get('preset', 'model')}"
        channels = self.metadata["input"].get("channels", {"kind": "magnetic_vector", "unit": "uT"})
        self.magnetic_ut = channels["kind"] == "magnetic_vector" and channels["unit"] == "uT"
        # models exported before board layouts existed were all trained on the SuperMag board
        self.board_layout = str(self.metadata.get("board_layout", DEFAULT_BOARD_LAYOUT))
        self._check_graph()
        self.image_symmetry = str(self.metadata.get("image_symmetry", "none")) if image_symmetry == "stored" \
            else image_symmetry
        self._image_group = image_subgroup(self.input_shape, self.output_shape, self.image_symmetry)
        self._one = None
        if samples == 1 and threads == 1 and one_reading_graph and len(self._image_group) == 1:
            meta_in = self.metadata["input"]
            centre, width = ((np.asarray(meta_in["offset"]), np.asarray(meta_in["spread"])) if meta_in.get("offset")
                             else (0.0, 0.3 * float(meta_in.get("clamp_ut", 500.0))))
            self._one = open_one_reading(ort, self.session, where=str(self.path), options=options,
                                         providers=list(providers), input_shape=self.input_shape,
                                         output_shape=self.output_shape, latent=self.latent, probe_centre=centre,
                                         probe_width=width, error=ModelFileError)
        #: whether single readings run through the file's one-reading graph (False with samples > 1, threads
        #: other than 1, one_reading_graph=False, an image averaged over symmetric copies (a batch of them), and
        #: for files exported before it)
        self.one_reading = self._one is not None
        self.angle_head = open_angle_head(ort, self.session, where=str(self.path), options=options,
                                          providers=list(providers), input_shape=self.input_shape,
                                          error=ModelFileError) if angle_head else None

    def _check_graph(self) -> None:
        """Refuse a graph that is not the one its metadata describes (metadata copied onto another model):
        input and output names, static dims and dtypes, then one all-zero reading for the output image size
        (exported graphs leave it symbolic)."""
        meta_in, meta_noise = self.metadata["input"], self.metadata["noise"]
        want_in = {meta_in["name"]: ["N", *self.input_shape], meta_noise["name"]: ["N", "K", self.latent]}
        want_out = {name: ["N", *self.output_shape] for name in self.metadata["output"]["names"]}
        graph_in = {i.name: (i.shape, i.type) for i in self.session.get_inputs()}
        graph_out = {o.name: (o.shape, o.type) for o in self.session.get_outputs()}
        problem = _signature_mismatch(graph_in, graph_out, want_in, want_out)
        if not problem:
            zeros = {name: np.zeros([1 if isinstance(d, str) else d for d in dims], np.float32)
                     for name, dims in want_in.items()}
            try:
                shapes = [tuple(np.shape(o)) for o in self.session.run(None, zeros)]
            except Exception as e:  # onnxruntime's own exception types
                shapes, problem = [], f"a graph that fails on one zero reading ({type(e).__name__})"
            if not problem and shapes != [(1, *self.output_shape)] * len(want_out):
                problem = f"outputs of shape {shapes} for one reading"
        if problem:
            raise ModelFileError(
                f"{self.path}: the graph does not match its tactile_manip metadata ({problem}): the graph maps "
                f"{_describe(graph_in)} -> {_describe(graph_out)}; the metadata describes "
                f"{_describe({n: (d, 'tensor(float)') for n, d in want_in.items()})} -> "
                f"{_describe({n: (d, 'tensor(float)') for n, d in want_out.items()})}; export the model again "
                "with `tactile-manip export` (metadata copied onto another graph is refused)")

    def _check_output(self, depth: np.ndarray, spread: np.ndarray | None) -> None:
        # min and max propagate NaN and show inf: two reductions instead of an isfinite pass
        values = [float(depth.min()), float(depth.max())]
        if spread is not None:
            values += [float(spread.min()), float(spread.max())]
        if not all(math.isfinite(v) for v in values):
            raise ModelFileError(f"{self.path}: the model produced non-finite output; the file may be corrupt")

    def _run(self, fields_ut: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        if len(self._image_group) == 1:
            return self._run_once(fields_ut)
        parts = [average_images(self._run_once, fields_ut[i:i + SYMMETRY_CHUNK], self._image_group)
                 for i in range(0, len(fields_ut), SYMMETRY_CHUNK)]  # bounds the memory of the copies' batch
        spread = None if parts[0][1] is None else np.concatenate([p[1] for p in parts])
        return (parts[0][0] if len(parts) == 1 else np.concatenate([p[0] for p in parts])), spread

    def _run_once(self, fields_ut: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        n = len(fields_ut)
        if n == 1 and self._one is not None:
            depth = self._one.run(None, {"field_ut": fields_ut})[0]
            self._check_output(depth, None)
            return depth, None
        if self.samples == 1:
            eps = np.zeros((n, 1, self.latent), np.float32)
        else:
            eps = self._rng.standard_normal((n, self.samples, self.latent)).astype(np.float32)
        depth, spread = self.session.run(None, {"field_ut": fields_ut, "eps": eps})
        spread = spread if self.samples > 1 else None  # one sample: no spread to check or return
        self._check_output(depth, spread)
        return depth, spread


def _signature_mismatch(graph_in: dict, graph_out: dict, want_in: dict, want_out: dict) -> str:
    """What differs between a graph's (name -> (dims, type)) inputs/outputs and the wanted dims; "" if none.

    Symbolic graph dims (str) match anything; the wanted "N" / "K" dims are free.
    """
    if set(graph_in) != set(want_in) or list(graph_out) != list(want_out):
        return "other input/output names"
    if any(t != "tensor(float)" for _, t in [*graph_in.values(), *graph_out.values()]):
        return "a tensor that is not float32"
    for name, (dims, _) in graph_in.items():
        want = want_in[name]
        if len(dims) != len(want) or any(isinstance(g, int) and isinstance(w, int) and g != w
                                         for g, w in zip(dims, want)):
            return f"input {name} of other dimensions"
    return ""


def _describe(tensors: dict) -> str:
    """``(name [dims] dtype, ...)`` of a (name -> (dims, onnxruntime type)) mapping."""
    return "(" + ", ".join(f"{n} {list(d)} {t.removeprefix('tensor(').rstrip(')')}"
                           for n, (d, t) in tensors.items()) + ")"


PARTIAL_SUFFIX = ".partial"  # what an export's file is called until its parity check passed


def recipe_of(path: Path) -> str:
    """Where the recipe that made the model at ``path`` is written: its card beside it (a shipped model's
    ``models/NAME.md``), else the training config its metadata stores."""
    card = path.with_suffix(".md")
    return str(card) if card.is_file() else "the train_config its metadata stores"


def read_metadata(path: str | Path) -> dict[str, Any]:
    """The ``tactile_manip`` metadata of an exported model, validated in itself
    (:func:`~tactile_manip.perception.model_metadata.check_metadata`; the loaders compare it with the graph).
    Raises :class:`ModelFileError`."""
    path = Path(path)
    if path.name.endswith(PARTIAL_SUFFIX):
        raise ModelFileError(f"{path}: an unfinished export (export writes {PARTIAL_SUFFIX} while it checks the "
                             "model, and renames it only once the check passed): export the model again")
    if not path.is_file():
        raise ModelFileError(missing_model_message(path))
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
    if not isinstance(meta, dict) or meta.get("format_version") != SUPPORTED_FORMAT:
        version = meta.get("format_version") if isinstance(meta, dict) else None
        raise ModelFileError(f"{path}: model format {version!r}, this code reads {SUPPORTED_FORMAT}")
    check_metadata(meta, path=path)  # the metadata alone; the loaders check it against the graph too
    return meta


class InterpolationReconstructor(Reconstructor):
    """Baseline: one channel's map (z of a magnetic reading) upsampled to the output size, then
    ``depth = max(gain * b + offset, 0)``.

    The upsampling maps each output pixel centre to taxel-grid coordinates (taxels at pitch ``pitch_mm``, one
    value or (rows, columns), centred on the pad) and interpolates with a spline of ``order`` (1: bilinear,
    3: bicubic), holding the edge values beyond the outer taxels. ``gain`` (mm/uT for the magnetic sensor:
    image unit per reading unit) and ``offset`` come from :meth:`fit`.
    """

    order = 1

    def __init__(self, *, gain_mm_per_ut: float, offset_mm: float, output_shape: tuple[int, int] = (200, 200),
                 pixel_mm: float = 0.1, pitch_mm: float | tuple[float, float] = 5.0,
                 input_shape: tuple[int, int, int] = (4, 4, 3), channel: int = 2) -> None:
        if not (np.isfinite(gain_mm_per_ut) and np.isfinite(offset_mm)):
            raise ValueError(f"{self.name}: gain and offset must be finite, got {gain_mm_per_ut}, {offset_mm}")
        self.gain, self.offset = float(gain_mm_per_ut), float(offset_mm)
        self.output_shape, self.pixel_mm = tuple(output_shape), float(pixel_mm)
        pitch = np.broadcast_to(np.asarray(pitch_mm, float), (2,))
        self.pitch_mm = float(pitch[0]) if pitch[0] == pitch[1] else (float(pitch[0]), float(pitch[1]))
        self.input_shape = tuple(input_shape)
        if not 0 <= channel < self.input_shape[-1]:
            raise ValueError(f"{self.name}: channel {channel} is not one of the reading's {self.input_shape[-1]}")
        self.channel = int(channel)
        self._coords = self._grid_coords()

    @classmethod
    def geometry(cls, readings_shape: tuple[int, ...], image_shape: tuple[int, int], pixel_mm: float | None,
                 channel: int) -> dict[str, Any]:
        """Constructor arguments for taxels spread evenly over the image (as on the simulated pad: 4 chips at
        5 mm over 200 px of 0.1 mm); an unknown pixel size counts in pixels."""
        (rows, cols, chans), (h, w) = tuple(readings_shape[-3:]), image_shape
        px = pixel_mm or 1.0
        return {"pixel_mm": px, "pitch_mm": (h * px / rows, w * px / cols), "input_shape": (rows, cols, chans),
                "channel": channel}

    def _grid_coords(self) -> np.ndarray:
        h, w = self.output_shape
        rows, cols = self.input_shape[:2]
        pitch_row, pitch_col = np.broadcast_to(np.asarray(self.pitch_mm, float), (2,))
        x = (np.arange(w) - (w - 1) / 2) * self.pixel_mm
        y = -(np.arange(h) - (h - 1) / 2) * self.pixel_mm
        col = x / pitch_col + (cols - 1) / 2
        row = -y / pitch_row + (rows - 1) / 2
        rr, cc = np.meshgrid(row, col, indexing="ij")
        return np.stack([rr, cc])

    def upsample(self, fields_ut: np.ndarray) -> np.ndarray:
        """(N, R, C, A) -> (N, H, W) upsampled maps of ``channel`` (z: the magnetic field's z axis, uT)."""
        return np.stack([ndimage.map_coordinates(f[..., self.channel].astype(np.float64), self._coords, order=self.order,
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
                "pixel_mm": self.pixel_mm, "pitch_mm": self.pitch_mm, "input_shape": list(self.input_shape),
                "channel": self.channel}


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
    if not key.endswith(".onnx") and not resolve_model_path(key).exists():
        raise ModelFileError(f"unknown reconstructor {key!r}: use 'bilinear', 'bicubic', a shipped model's name "
                             f"({', '.join(SHIPPED_MODELS)}) or a path to an .onnx model")
    return OnnxReconstructor(key, **kwargs)
