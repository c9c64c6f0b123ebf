"""Fixtures shared across layers: ONNX graphs carrying the shipped model's metadata (for load-time checks);
the real eFlesh probe-rig runs where they are on disk.

Also the report's torch line: without torch about a hundred tests skip, so the header and the summary say so
in words instead of leaving it to a count of skips. And a run ends with its summary line: the caches that hold
nanobind objects are emptied before the interpreter exits (see :func:`pytest_unconfigure`).
"""

from __future__ import annotations

import gc
import importlib.util
import os
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from checks import TORCH_MISSING

SHIPPED_MODEL = Path(__file__).resolve().parents[1] / "models" / "supermag.onnx"
SHIPPED_CONTACT_MODEL = Path(__file__).resolve().parents[1] / "models" / "contact_supermag.onnx"
EFLESH_ENV = "TACTILE_MANIP_EFLESH_DIR"  # folder of the eFlesh characterisation runs (spatial_*/, normal_*/)


@pytest.fixture(scope="session")
def eflesh_dir() -> Path:
    """The eFlesh development runs (two folders of sensor.csv, sensor_post_baselines.csv, states.csv): from
    ``$TACTILE_MANIP_EFLESH_DIR``, else ``shared/data/eflesh_dev`` beside the checkout; skipped when absent."""
    root = Path(__file__).resolve().parents[1]
    candidates = [Path(os.environ[EFLESH_ENV])] if os.environ.get(EFLESH_ENV) else []
    candidates += [root.parent / "shared" / "data" / "eflesh_dev", root.parents[1] / "shared" / "data" / "eflesh_dev"]
    for folder in candidates:
        if (folder / "spatial_20250316_155729" / "states.csv").is_file():
            return folder
    pytest.skip(f"the eFlesh runs are not on this machine (set {EFLESH_ENV} to their folder)")


def _torch_installed() -> bool:
    try:
        return importlib.util.find_spec("torch") is not None
    except (ImportError, ValueError):
        return False


def pytest_report_header(config) -> str | None:
    return None if _torch_installed() else f"WARNING: {TORCH_MISSING}; every test that needs it is skipped"


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:
    skipped = [r for r in terminalreporter.stats.get("skipped", []) if TORCH_MISSING in str(r.longrepr)]
    if skipped:
        terminalreporter.write_sep("!", f"{len(skipped)} tests or test files SKIPPED: {TORCH_MISSING}", red=True,
                                   bold=True)


def pytest_unconfigure(config) -> None:
    """Empties the functools caches of the packages holding nanobind objects before the interpreter exits.

    roboticstoolbox keeps its robots in class-level ``lru_cache``s (``BaseRobot.ets``, ``_getlink``) and the twin
    caches its kinematics; with torch loaded, those objects (roboticstoolbox ``_ETObj``, spatialgeometry
    ``_Node``) outlive the extensions' own cleanup at exit, and nanobind prints some 70 lines of leak report
    after the summary line. Freed here, while the extensions are still alive, they leave nothing to report.
    """
    for name, module in list(sys.modules.items()):
        if module is None or name.partition(".")[0] not in ("roboticstoolbox", "spatialgeometry", "tactile_manip"):
            continue
        for obj in list(vars(module).values()):
            for member in (obj, *(vars(obj).values() if isinstance(obj, type) else ())):
                if callable(getattr(member, "cache_clear", None)):
                    member.cache_clear()
    gc.collect()


@pytest.fixture
def graph_with_shipped_metadata(tmp_path: Path) -> Callable[[str], Path]:
    """Factory: a small foreign ONNX graph with the shipped model's metadata_props copied onto it.

    ``kind``: "identity" (one x (1, 48) -> y Identity node, the names and layout of another model),
    "input_dims" (our names, field_ut (N, 5, 5, 3)), "image_size" (our names and inputs, 100x100 outputs).
    """
    onnx = pytest.importorskip("onnx")
    from onnx import TensorProto, helper, numpy_helper

    props = [(p.key, p.value) for p in onnx.load(str(SHIPPED_MODEL), load_external_data=False).metadata_props]

    def make(kind: str) -> Path:
        if kind == "identity":
            inputs = [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 48])]
            outputs = [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 48])]
            nodes = [helper.make_node("Identity", ["x"], ["y"])]
        else:
            rows = 5 if kind == "input_dims" else 4
            side = 100 if kind == "image_size" else 200
            inputs = [helper.make_tensor_value_info("field_ut", TensorProto.FLOAT, ["batch", rows, 4, 3]),
                      helper.make_tensor_value_info("eps", TensorProto.FLOAT, ["batch", "samples", 32])]
            outputs = [helper.make_tensor_value_info(n, TensorProto.FLOAT, ["batch", "h", "w"])
                       for n in ("depth_mm", "spread_mm")]
            image = numpy_helper.from_array(np.zeros((1, side, side), np.float32), "image")
            nodes = [helper.make_node("Constant", [], ["c"], value=image),
                     helper.make_node("Identity", ["c"], ["depth_mm"]),
                     helper.make_node("Identity", ["c"], ["spread_mm"])]
        model = helper.make_model(helper.make_graph(nodes, kind, inputs, outputs),
                                  opset_imports=[helper.make_opsetid("", 17)])
        for key, value in props:
            entry = model.metadata_props.add()
            entry.key, entry.value = key, value
        onnx.checker.check_model(model)
        path = tmp_path / f"{kind}.onnx"
        onnx.save(model, str(path))
        return path

    return make


def _labelled_presses(n: int = 600, *, seed: int = 0):
    """A small synthetic labelled-press dataset on a 3 x 3 board (corners unused), one run sampled at 20 Hz:
    the field of each used cell falls off with the distance to the contact and scales with the force."""
    from tactile_manip.data import PairedDataset

    rng = np.random.default_rng(seed)
    x, y = rng.uniform(-5, 5, n), rng.uniform(-5, 5, n)
    force = rng.uniform(0, 10, n)
    cells = [(0, 1), (1, 0), (1, 1), (1, 2), (2, 1)]
    readings = np.zeros((n, 3, 3, 3), np.float32)
    for r, c in cells:
        cx, cy = (c - 1) * 6.0, (1 - r) * 6.0
        dx, dy = x - cx, y - cy
        fall = force * np.exp(-(dx ** 2 + dy ** 2) / 50.0)
        readings[:, r, c] = np.stack([20 * fall * dx / 5, 20 * fall * dy / 5, 60 * fall], axis=1)
    readings += rng.normal(0, 1.0, readings.shape).astype(np.float32)
    for r, c in [(0, 0), (0, 2), (2, 0), (2, 2)]:
        readings[:, r, c] = 0
    split = np.where(np.arange(n) < int(0.8 * n), "train", "test")
    return PairedDataset(readings=readings, images=None, split=split, groups=np.zeros(n, np.int64),
                         targets=np.stack([x, y, force], 1).astype(np.float32),
                         target_names=("x_mm", "y_mm", "force_n"),
                         extras={"time_s": np.arange(n) * 0.05}, provenance={"layout": "anyskin-5"})


@pytest.fixture(scope="session")
def labelled_presses():
    """Factory ``labelled_presses(n=600, seed=0)`` of a synthetic labelled-press dataset (one run, 20 Hz, 3 x 3
    board with its corners unused; targets x_mm, y_mm, force_n; chronological 80/20 split)."""
    return _labelled_presses


@pytest.fixture(scope="session")
def contact_model_files(tmp_path_factory):
    """(dataset .npz, run folder, exported .onnx) of a tiny contact model trained on :func:`labelled_presses`."""
    pytest.importorskip("torch", reason="training the contact model needs torch")
    pytest.importorskip("onnxruntime", reason="exporting the contact model checks it on onnxruntime")
    from tactile_manip.data import save_dataset
    from tactile_manip.learning.contact.export import export_contact_onnx
    from tactile_manip.learning.contact.train import ContactTrainConfig, train_contact

    root = tmp_path_factory.mktemp("contact")
    save_dataset(root / "presses.npz", _labelled_presses())
    cfg = ContactTrainConfig(hidden=32, members=2, epochs=40, patience=40, batch_size=64, lr=5e-3, threads=1)
    train_contact(cfg, [root / "presses.npz"], root / "run")
    export_contact_onnx(root / "run" / "best.pt", root / "contact.onnx")
    return root / "presses.npz", root / "run", root / "contact.onnx"


@pytest.fixture
def contact_model_of_layout(tmp_path: Path) -> Callable[[str], Path]:
    """Factory ``make(layout, **metadata)``: the shipped SuperMag contact model with ``board_layout`` in its
    metadata set to ``layout`` and the other top-level metadata entries given replaced (e.g. ``targets=...``).
    For a layout of another reading grid (e.g. "anyskin-5": a model of another board) the graph is a small one
    taking that grid's readings (zero means, unit sigmas), so that its metadata agrees with it."""
    onnx = pytest.importorskip("onnx", reason="rewriting a model's metadata needs onnx (pip install -e '.[train]')")
    import json

    from tactile_manip.perception.reconstruct import METADATA_KEY
    from tactile_manip.boards import load_board

    def make(layout: str, **metadata) -> Path:
        proto = onnx.load(str(SHIPPED_CONTACT_MODEL))
        grid = load_board(layout).grid
        if grid != (4, 4):
            proto = _contact_graph_of_grid(proto, grid)
        for prop in proto.metadata_props:
            if prop.key == METADATA_KEY:
                meta = json.loads(prop.value)
                meta["input"]["shape"] = ["batch", meta["input"]["shape"][1], *grid, 3]
                prop.value = json.dumps({**meta, "board_layout": layout, **metadata})
        path = tmp_path / f"contact_{layout}_{len(list(tmp_path.glob('contact_*.onnx')))}.onnx"
        onnx.save(proto, str(path))
        return path

    return make


def _contact_graph_of_grid(shipped, grid: tuple[int, int]):
    """A contact graph of ``shipped``'s names and outputs (K targets) taking (N, 1, R, C, 3) readings of ``grid``:
    mean 0 and sigma 1 for every target, with ``shipped``'s metadata."""
    from onnx import TensorProto, helper, numpy_helper

    targets = [d.dim_value for d in shipped.graph.output[0].type.tensor_type.shape.dim][1]
    weights = numpy_helper.from_array(np.zeros((grid[0] * grid[1] * 3, targets), np.float32), "w")
    ones = numpy_helper.from_array(np.ones(targets, np.float32), "one")
    nodes = [helper.make_node("Flatten", ["field_ut"], ["flat"], axis=1),
             helper.make_node("MatMul", ["flat", "w"], ["mean"]),
             helper.make_node("Add", ["mean", "one"], ["sigma"])]
    inputs = [helper.make_tensor_value_info("field_ut", TensorProto.FLOAT, ["batch", 1, *grid, 3])]
    outputs = [helper.make_tensor_value_info(n, TensorProto.FLOAT, ["batch", targets]) for n in ("mean", "sigma")]
    graph = helper.make_graph(nodes, "contact_of_grid", inputs, outputs, initializer=[weights, ones])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = shipped.ir_version
    for prop in shipped.metadata_props:
        entry = model.metadata_props.add()
        entry.key, entry.value = prop.key, prop.value
    return model
