"""The angle head a pose model may carry beside its image graphs: the contact's axis straight from the reading.

The head (trained by ``tactile-manip train`` with a ``kind = "angle_head"`` config, attached to a model file by
``tactile-manip export --checkpoint RUN/best.pt --attach-to MODEL.onnx``) maps ``field_ut`` (N, R, C, A) to
``axis`` (N, 2), the vector ``kappa (cos 2t, sin 2t)`` of a von Mises distribution over the doubled axis angle.
It travels base64-encoded under the metadata key :data:`ANGLE_HEAD_KEY` of the model file, with its record
(training data, validation figures) as JSON under :data:`ANGLE_HEAD_META_KEY`, so that image model and head
cannot be copied apart.

:func:`within_probability` turns a concentration into the probability that the axis is within a tolerance
(the von Mises mass of the doubled angle within twice the tolerance), which the pose estimator compares with
the image route's calibrated confidence.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
from typing import Any

import numpy as np

from tactile_manip.errors import TactileManipError

ANGLE_HEAD_KEY = "tactile_manip.angle_head_onnx"
ANGLE_HEAD_META_KEY = "tactile_manip.angle_head"
_LOG_KAPPA = np.linspace(-6.0, 12.0, 721)  # grid of log concentrations for the probability table


class AngleHead:
    """An open angle head: :meth:`axes` of readings, and the record it was attached with (:attr:`record`)."""

    def __init__(self, session: Any, record: dict[str, Any]) -> None:
        self.session = session
        self.record = record
        self._feed = {"field_ut": None}

    def axes(self, fields_ut: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Axis angles (rad, (-pi/2, pi/2]) and concentrations (N,) of checked readings (N, R, C, A)."""
        self._feed["field_ut"] = np.ascontiguousarray(fields_ut, dtype=np.float32)
        axis = self.session.run(None, self._feed)[0].astype(np.float64)
        return 0.5 * np.arctan2(axis[:, 1], axis[:, 0]), np.hypot(axis[:, 0], axis[:, 1])

    def axis(self, field_ut: np.ndarray) -> tuple[float, float]:
        """Axis angle (rad) and concentration of one checked reading (R, C, A)."""
        self._feed["field_ut"] = np.ascontiguousarray(field_ut[None], dtype=np.float32)
        a, b = (float(v) for v in self.session.run(None, self._feed)[0][0])
        return 0.5 * math.atan2(b, a), math.hypot(a, b)


def _probability_table(tolerance_rad: float) -> np.ndarray:
    """P(|doubled error| <= 2 tolerance) on the :data:`_LOG_KAPPA` grid (von Mises, numerically integrated)."""
    x = np.linspace(-math.pi, math.pi, 8001)[:-1]  # one period on a uniform grid: sums are the integrals
    kappa = np.exp(_LOG_KAPPA)[:, None]
    density = np.exp(kappa * (np.cos(x)[None] - 1.0))  # scaled by exp(-kappa): the ratio is unchanged
    inside = np.abs(x) <= 2 * tolerance_rad
    return (density * inside).sum(axis=1) / density.sum(axis=1)


_TABLES: dict[float, np.ndarray] = {}


def within_probability(kappa: float | np.ndarray, tolerance_rad: float) -> float | np.ndarray:
    """Probability that an axis estimate with von Mises concentration ``kappa`` (of the doubled angle) is
    within ``tolerance_rad`` of the truth."""
    table = _TABLES.get(tolerance_rad)
    if table is None:
        table = _TABLES[tolerance_rad] = _probability_table(tolerance_rad)
    log_k = np.log(np.maximum(kappa, 1e-300))
    p = np.interp(log_k, _LOG_KAPPA, table)
    return float(p) if np.ndim(kappa) == 0 else p


def open_angle_head(ort: Any, main: Any, *, where: str, options: Any, providers: list[str],
                    input_shape: tuple[int, int, int], error: type[TactileManipError]) -> AngleHead | None:
    """The angle head in ``main``'s file (None when it has none), opened like ``main``.

    Raises ``error`` (naming ``where``) when it cannot be decoded or loaded, or maps another signature than
    ``field_ut`` (N, *input_shape) -> ``axis`` (N, 2).
    """
    meta = main.get_modelmeta().custom_metadata_map
    raw = meta.get(ANGLE_HEAD_KEY)
    if raw is None:
        return None
    fix = "attach the head again with `tactile-manip export --checkpoint RUN/best.pt --attach-to MODEL`"
    try:
        graph = base64.b64decode(raw.encode("ascii"), validate=True)
        record = json.loads(meta.get(ANGLE_HEAD_META_KEY, "{}"))
    except (binascii.Error, UnicodeEncodeError, ValueError) as e:
        raise error(f"{where}: its angle head ({ANGLE_HEAD_KEY}) cannot be decoded ({e}); {fix}") from e
    try:
        session = ort.InferenceSession(graph, sess_options=options, providers=providers)
    except Exception as e:  # onnxruntime raises its own exception types
        raise error(f"{where}: onnxruntime cannot load its angle head ({ANGLE_HEAD_KEY}): {e}; {fix}") from e
    signature = ([(i.name, list(i.shape)[1:], i.type) for i in session.get_inputs()],
                 [(o.name, list(o.shape)[1:], o.type) for o in session.get_outputs()])
    want = ([("field_ut", list(input_shape), "tensor(float)")], [("axis", [2], "tensor(float)")])
    if signature != want:
        raise error(f"{where}: its angle head maps {signature[0]} -> {signature[1]}, not {want[0]} -> {want[1]}; "
                    f"{fix}")
    return AngleHead(session, record)
