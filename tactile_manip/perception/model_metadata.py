"""What the ``tactile_manip`` metadata of an exported model must say, and that its graph agrees with it.

The metadata is JSON beside the graph; everything inference needs is read from it (input and output shapes,
target names and units, the board layout, the context). A file whose metadata was edited (targets renamed,
another board layout, another context length) would otherwise load and give numbers under the wrong names.
:func:`check_metadata` refuses it with a :class:`ModelFileError` naming the file and the field:

- every field has its type (``context.frames`` an integer, ``targets.names`` a list of strings, ...);
- shapes are positive integers; the board layout's reading grid (``tactile_manip.boards``; ``grid-RxC`` for
  other grids) is the input's rows and columns;
- a contact model's targets and units pair up by their suffixes (``x_mm`` in mm, ``force_n`` in N), its
  ``context.frames`` is the input's frame axis, within 1..:data:`MAX_CONTEXT_FRAMES`;
- given the onnxruntime session, a contact graph's input takes those frames and cells and its outputs give one
  value per target. An image model's graph is compared by its loader, which also runs it once
  (:class:`~tactile_manip.perception.reconstruct.OnnxReconstructor`).

Both loaders call it (:class:`~tactile_manip.perception.reconstruct.OnnxReconstructor`,
:class:`~tactile_manip.perception.contact.ContactEstimator`), and :func:`~tactile_manip.perception.reconstruct.
read_metadata` checks the metadata alone.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

from tactile_manip.errors import DatasetError, TactileManipError
from tactile_manip.perception.board_symmetry import IMAGE_SYMMETRIES

MAX_CONTEXT_FRAMES = 64   # the training config's bound (learning/contact/model.py)
MAX_GAP_S = 3600.0        # the training config's bound on context.max_gap_s
KINDS = ("image", "contact")
_NUMBER = (int, float)
# type of each top-level field where present (the loaders read these; the rest is the record of the run)
TOP_LEVEL = {"format_version": int, "kind": str, "package_version": str, "board_layout": str, "preset": str,
             "data_fingerprint": str, "parameters": int, "input": dict, "output": dict, "noise": dict,
             "context": dict, "targets": dict, "normalisation": dict, "sigma_calibration": dict,
             "model_config": dict, "train_config": dict, "training": dict, "training_data": dict, "metrics": dict,
             "one_reading": dict, "image_position_weight": _NUMBER, "image_symmetry": str, "board": dict}
_GRID_NAME = re.compile(r"grid-(\d+)x(\d+)")


class ModelFileError(TactileManipError, ValueError):
    """A model file is missing, unreadable, not ours, or does not match the readings."""


def check_metadata(meta: Any, session: Any = None, *, path: str | Path) -> None:
    """Refuse metadata ``meta`` of the model file ``path`` that is inconsistent in itself or, given its
    onnxruntime ``session``, with the graph (see the module docstring).

    Raises:
        ModelFileError: the path, the field and what is wrong with it.
    """
    check = _Checker(path)
    if not isinstance(meta, dict):
        raise check.fail("(the whole)", f"is a {type(meta).__name__}, not a JSON object")
    for name, kind in TOP_LEVEL.items():
        if name in meta:
            check.typed(meta[name], kind, name)
    kind = meta.get("kind", "image")
    if kind not in KINDS:
        raise check.fail("kind", f"is {kind!r}, not one of {', '.join(KINDS)}")
    inp = check.typed(meta.get("input"), dict, "input")
    check.typed(inp.get("name"), str, "input.name")
    shape = check.typed(inp.get("shape"), list, "input.shape")
    frames = kind == "contact"
    if len(shape) != 4 + frames:
        what = "[batch, frames, rows, cols, channels]" if frames else "[batch, rows, cols, channels]"
        raise check.fail("input.shape", f"is {shape}, not {what}")
    dims = [check.count(d, f"input.shape[{i + 1}]") for i, d in enumerate(shape[1:])]
    if "channels" in inp:
        channels = check.typed(inp["channels"], dict, "input.channels")
        for key in ("kind", "unit"):
            check.typed(channels.get(key), str, f"input.channels.{key}")
    _check_layout(check, meta.get("board_layout"), tuple(dims[frames:frames + 2]))
    if frames:
        _check_contact(check, meta, dims)
        if session is not None:
            _check_contact_graph(check, meta, dims, session)
    else:
        _check_image(check, meta)


class _Checker:
    """Type and range checks whose failures name the file and the field."""

    def __init__(self, path: str | Path) -> None:
        self.path = path

    def fail(self, field: str, problem: str) -> ModelFileError:
        return ModelFileError(f"{self.path}: metadata field {field} {problem}; export the model again with "
                              "`tactile-manip export` (edited metadata is refused)")

    def typed(self, value: Any, kind: type | tuple[type, ...], field: str) -> Any:
        names = {dict: "a JSON object", list: "a list", str: "a string", int: "an integer"}
        ok = isinstance(value, kind) and not (isinstance(value, bool) and kind in (int, _NUMBER))
        if not ok:
            what = "a number" if kind == _NUMBER else names.get(kind, getattr(kind, "__name__", str(kind)))
            raise self.fail(field, f"is {value!r}, not {what}" if value is not None else f"is missing (needs {what})")
        return value

    def count(self, value: Any, field: str, *, high: int | None = None) -> int:
        self.typed(value, int, field)
        if value < 1 or (high is not None and value > high):
            raise self.fail(field, f"is {value}, not in [1, {high}]" if high else f"is {value}, not >= 1")
        return value

    def number(self, value: Any, field: str, low: float, high: float) -> float:
        self.typed(value, _NUMBER, field)
        if not (math.isfinite(value) and low <= value <= high):
            raise self.fail(field, f"is {value!r}, not in [{low:g}, {high:g}]")
        return float(value)


def _check_layout(check: _Checker, layout: Any, grid: tuple[int, int]) -> None:
    """The board layout's reading grid (a known board's, or ``grid-RxC``) must be the input's rows x cols."""
    from tactile_manip.boards import load_board

    if layout is None:  # files from before board layouts: the loaders take them as SuperMag models
        return
    if (m := _GRID_NAME.fullmatch(layout)) is not None:
        want = (int(m.group(1)), int(m.group(2)))
    else:
        try:
            want = tuple(load_board(layout).grid)
        except (ValueError, OSError):  # a board this machine does not know (a dataset's own name): nothing to compare
            return
    if want != grid:
        raise check.fail("board_layout", f"is {layout!r}, a {want[0]}x{want[1]} reading grid, but the input takes "
                                         f"{grid[0]}x{grid[1]} readings")


def _check_image(check: _Checker, meta: dict) -> None:
    out = check.typed(meta.get("output"), dict, "output")
    names = check.typed(out.get("names"), list, "output.names")
    for i, name in enumerate(names):
        check.typed(name, str, f"output.names[{i}]")
    shape = check.typed(out.get("shape"), list, "output.shape")
    if len(shape) != 3:
        raise check.fail("output.shape", f"is {shape}, not [batch, height, width]")
    for i, d in enumerate(shape[1:]):
        check.count(d, f"output.shape[{i + 1}]")
    check.number(out.get("pixel_mm"), "output.pixel_mm", 1e-6, 1e3)
    noise = check.typed(meta.get("noise"), dict, "noise")
    check.typed(noise.get("name"), str, "noise.name")
    latent = check.typed(noise.get("shape"), list, "noise.shape")
    if len(latent) != 3:
        raise check.fail("noise.shape", f"is {latent}, not [batch, samples, latent]")
    check.count(latent[2], "noise.shape[2]")
    if meta.get("image_symmetry", "none") not in IMAGE_SYMMETRIES:
        raise check.fail("image_symmetry", f"is {meta['image_symmetry']!r}, not one of {', '.join(IMAGE_SYMMETRIES)}")


def _check_contact(check: _Checker, meta: dict, dims: list[int]) -> None:
    from tactile_manip.data.targets import target_unit

    frames = check.count(dims[0], "input.shape[1]", high=MAX_CONTEXT_FRAMES)
    context = meta.get("context", {})
    if "frames" in context:
        given = check.count(context["frames"], "context.frames", high=MAX_CONTEXT_FRAMES)
        if given != frames:
            raise check.fail("context.frames", f"is {given}, but input.shape[1] (the frames) is {frames}")
    if "max_gap_s" in context:
        check.number(context["max_gap_s"], "context.max_gap_s", 0.0, MAX_GAP_S)
    if context.get("frame_period_s") is not None:
        check.number(context["frame_period_s"], "context.frame_period_s", 1e-9, MAX_GAP_S)
    targets = check.typed(meta.get("targets"), dict, "targets")
    names = check.typed(targets.get("names"), list, "targets.names")
    units = check.typed(targets.get("units"), list, "targets.units")
    if not names:
        raise check.fail("targets.names", "is empty")
    for i, name in enumerate(names):
        check.typed(name, str, f"targets.names[{i}]")
    twice = [n for i, n in enumerate(names) if n in names[:i]]
    if twice:
        raise check.fail("targets.names", f"names {twice[0]!r} twice ({', '.join(names)})")
    if len(units) != len(names):
        raise check.fail("targets.units", f"has {len(units)} units for {len(names)} targets ({', '.join(names)})")
    for i, (name, unit) in enumerate(zip(names, units)):
        try:
            want = target_unit(name)
        except DatasetError:
            raise check.fail(f"targets.names[{i}]", f"is {name!r}, a name without a unit suffix (_mm, _n, _rad)"
                             ) from None
        if unit != want:
            raise check.fail(f"targets.units[{i}]", f"is {unit!r}, but target {name!r} is in {want!r} (were names "
                                                    "or units reordered?)")
    out = meta.get("output", {})
    if "shape" in out:
        shape = check.typed(out["shape"], list, "output.shape")
        if len(shape) != 2 or shape[1] != len(names):
            raise check.fail("output.shape", f"is {shape}, not [batch, {len(names)}] for {len(names)} targets")


def _check_contact_graph(check: _Checker, meta: dict, dims: list[int], session: Any) -> None:
    """The graph's input takes the metadata's frames and cells; its outputs give one value per target."""
    name = meta["input"]["name"]
    graph_in = {i.name: list(i.shape) for i in session.get_inputs()}
    if name in graph_in and len(graph_in[name]) == len(dims) + 1:  # other names or ranks: the loader's message
        for axis, (want, got) in enumerate(zip(dims, graph_in[name][1:]), start=1):
            if isinstance(got, int) and got != want:
                field = "context.frames / input.shape[1]" if axis == 1 else f"input.shape[{axis}]"
                raise check.fail(field, f"is {want}, but the graph's input {name} {graph_in[name]} takes {got}")
    count = len(meta["targets"]["names"])
    for out in session.get_outputs():
        shape = list(out.shape)
        if len(shape) == 2 and isinstance(shape[1], int) and shape[1] != count:
            raise check.fail("targets.names", f"names {count} targets, but the graph's output {out.name} {shape} "
                                              f"gives {shape[1]} per sample")
