"""The one-reading graph an exported model carries beside its main graph, and its checks at load.

The main graph takes a batch of readings and K prior samples and ends in the mean and spread over the samples.
A control loop asks for one reading and one sample (the prior mean) at a time, where that generality costs: the
shape arithmetic of dynamic batch and sample dimensions, and a mean/spread tail whose spread is zero anyway.
``tactile-manip export`` therefore also writes the prior-mean reconstruction of exactly one reading,
``field_ut`` (1, R, C, A) -> ``depth_mm`` (1, H, W), with static shapes and without the tail, base64 under the
metadata key :data:`ONE_READING_KEY` of the same file, so the two cannot drift apart or be copied apart. On
the default model it takes about 10 % less network time on one thread with identical output
(docs/results/perception_measurements.md).

:func:`open_one_reading` opens it and refuses it unless it reproduces the main graph on probe readings.
Files exported before it existed have none, and their readers fall back to the main graph.
"""

from __future__ import annotations

import base64
import binascii
from typing import Any

import numpy as np

from tactile_manip.errors import TactileManipError

ONE_READING_KEY = "tactile_manip.one_reading_onnx"
#: largest |one-reading - main| depth at load, as a share of the probe image's largest value (at least 1 unit);
#: the two graphs are the same float32 arithmetic, a few 1e-7 apart
PARITY_TOLERANCE = 1e-4


def encode(onnx_bytes: bytes) -> str:
    """The metadata value that carries a serialised ONNX graph (the one-reading graph, an angle head)."""
    return base64.b64encode(onnx_bytes).decode("ascii")


def remove_from(proto: Any) -> None:
    """Remove the one-reading graph from an ``onnx.ModelProto``'s metadata, in place (e.g. after rewriting the
    main graph: quantising it, editing it), so readers run the main graph."""
    keep = [(p.key, p.value) for p in proto.metadata_props if p.key != ONE_READING_KEY]
    del proto.metadata_props[:]
    for key, value in keep:
        entry = proto.metadata_props.add()
        entry.key, entry.value = key, value


def open_one_reading(ort: Any, main: Any, *, where: str, options: Any, providers: list[str],
                     input_shape: tuple[int, int, int], output_shape: tuple[int, int], latent: int,
                     probe_centre: np.ndarray | float, probe_width: np.ndarray | float,
                     error: type[TactileManipError]) -> Any | None:
    """An onnxruntime session of the one-reading graph in ``main``'s file (None when it has none).

    ``main`` is the open session of the main graph; ``options`` and ``providers`` open the new one alike.
    Raises ``error`` (naming ``where``) when the graph cannot be decoded or loaded, has another signature
    than ``field_ut`` (1, *input_shape) -> ``depth_mm`` (1, *output_shape), or does not reproduce ``main`` at
    ``eps = 0`` on a zero reading and a random one drawn around ``probe_centre`` +- ``probe_width``.
    """
    raw = main.get_modelmeta().custom_metadata_map.get(ONE_READING_KEY)
    if raw is None:
        return None
    fix = "export the model again with `tactile-manip export`"
    try:
        graph = base64.b64decode(raw.encode("ascii"), validate=True)
    except (binascii.Error, UnicodeEncodeError) as e:
        raise error(f"{where}: its one-reading graph ({ONE_READING_KEY}) is not valid base64 ({e}); {fix}") from e
    try:
        session = ort.InferenceSession(graph, sess_options=options, providers=providers)
    except Exception as e:  # onnxruntime raises its own exception types
        raise error(f"{where}: onnxruntime cannot load its one-reading graph ({ONE_READING_KEY}): {e}; {fix}") from e
    signature = ([(i.name, list(i.shape), i.type) for i in session.get_inputs()],
                 [(o.name, list(o.shape), o.type) for o in session.get_outputs()])
    want = ([("field_ut", [1, *input_shape], "tensor(float)")], [("depth_mm", [1, *output_shape], "tensor(float)")])
    if signature != want:
        raise error(f"{where}: its one-reading graph maps {signature[0]} -> {signature[1]}, not {want[0]} -> "
                    f"{want[1]}; {fix}")
    rng = np.random.default_rng(0)
    probes = [np.zeros((1, *input_shape), np.float32),
              (probe_centre + probe_width * rng.uniform(-1.0, 1.0, (1, *input_shape))).astype(np.float32)]
    eps = np.zeros((1, 1, latent), np.float32)
    for probe in probes:
        ref = main.run(None, {"field_ut": probe, "eps": eps})[0]
        got = session.run(None, {"field_ut": probe})[0]
        worst = float(np.max(np.abs(got - ref)))
        if not worst <= PARITY_TOLERANCE * max(1.0, float(np.max(np.abs(ref)))):  # NaN fails too
            raise error(f"{where}: its one-reading graph differs from the main graph by {worst:.3g} on a probe "
                        f"reading: the two do not belong together; {fix}")
    return session
