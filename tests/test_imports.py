"""Importing the package and the simulator stays cheap: no heavy or optional package is pulled in, the
sensors and perception layers do not reach up into the simulator, the runtime (perception) does not reach up
into its evaluation, the data layer does not reach up into the sensors, and the wire formats and log files sit
below every layer but the core (docs/design.md, Layers).

Each runtime check runs in a fresh interpreter, since this test process has long since imported everything.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

import tactile_manip

PACKAGE = Path(tactile_manip.__file__).parent
# the sensors package that drives the simulator: the simulated sensor, the firmware emulator and their presses
SIMULATED = "sensors/simulated/"

REPOSITORY = Path(__file__).resolve().parents[1]

# what the byte formats (tactile_manip.wire, tactile_manip.logs) never import: every layer above the core
ABOVE_THE_FORMATS = ("data", "sim", "sensors", "collection", "perception", "robot", "behaviours", "trials", "learning",
                     "bench", "interop", "commands", "cli")

HEAVY = ("torch", "onnxruntime", "roboticstoolbox", "franky", "serial", "trimesh", "matplotlib", "cv2", "sklearn")


def _modules_after(code: str, condition: str) -> list[str]:
    """Run ``code`` in a fresh interpreter; return the modules ``m`` in its ``sys.modules`` for which the Python
    expression ``condition`` holds, sorted."""
    probe = f"{code}\nimport json, sys\nprint(json.dumps(sorted({{m for m in sys.modules if {condition}}})))"
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def _heavy_modules_after(code: str) -> list[str]:
    """Run ``code`` in a fresh interpreter; return the heavy top-level packages it left in ``sys.modules``."""
    return sorted({m.split(".")[0] for m in _modules_after(code, f"m.split('.')[0] in {list(HEAVY)!r}")})


@pytest.mark.parametrize("code", [
    "import tactile_manip",
    "import tactile_manip.sim.pair",
    "import tactile_manip.boards; tactile_manip.boards.load_board('eflesh')",
    "import tactile_manip.sim.board_press, tactile_manip.sim.magnets",
    "import tactile_manip.sim.dataset",
    "import tactile_manip.sensors",
    "import tactile_manip.logs.recording, tactile_manip.wire",
    "import tactile_manip.collection.camera, tactile_manip.collection.camera_opencv, tactile_manip.collection.camera_sim, "
    "tactile_manip.collection.vbts_calibration, tactile_manip.collection.collect, tactile_manip.collection.collect_sim",
    "import tactile_manip.perception.reconstruct, tactile_manip.perception.pose",
    "import tactile_manip.perception",
    "import tactile_manip.perception.contact, tactile_manip.perception.tactile_estimator",
    "import tactile_manip.evaluation",
    # the image metrics are numpy and scipy only; the gallery imports matplotlib inside its function, and the
    # contact baselines scikit-learn inside theirs
    "import tactile_manip.evaluation.metrics",
    "import tactile_manip.evaluation.images, tactile_manip.evaluation.contact, "
    "tactile_manip.evaluation.contact_baselines, tactile_manip.evaluation.pose_reference",
    # applying a fitted confidence calibration is numpy only (fitting one imports scikit-learn)
    "from tactile_manip.perception.confidence import ConfidenceCalibration; "
    "ConfidenceCalibration((0.1, 0.9), (0.2, 0.8))(0.5)",
    "import tactile_manip.robot, tactile_manip.robot.twin, tactile_manip.robot.safety, tactile_manip.robot.conformance",
    "import tactile_manip.behaviours.reorient, tactile_manip.behaviours.place",
    "import tactile_manip.trials.scene, tactile_manip.trials.runner, tactile_manip.trials.stats",
    # the registry of model kinds and the verbs' modules it names import torch only when a verb runs
    "import tactile_manip.learning.kinds, tactile_manip.learning.verbs, tactile_manip.learning.cvae.verbs, "
    "tactile_manip.learning.angle_head.verbs, tactile_manip.learning.contact.verbs",
    # the CLI parser imports every command module, and `--help` must stay fast
    "import tactile_manip.cli; tactile_manip.cli.build_parser()",
])
def test_import_pulls_in_no_heavy_package(code):
    assert _heavy_modules_after(code) == []


def test_probe_sees_a_heavy_import():
    """The probe itself works: an import of matplotlib (a core dependency) is reported."""
    assert _heavy_modules_after("import tactile_manip.plots; tactile_manip.plots._pyplot()") == ["matplotlib"]


def _imported_modules(path: Path, root: Path = PACKAGE) -> set[str]:
    """Every module ``path`` imports, anywhere in the file (also inside functions), as dotted absolute names
    (``root``: the package's folder, which relative imports are resolved against)."""
    package = ".".join(("tactile_manip", *path.relative_to(root).parent.parts))
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package.rsplit(".", node.level - 1)[0] if node.level else ""
            module = ".".join(p for p in (base, node.module or "") if p)
            names.add(module)
            names.update(f"{module}.{alias.name}" for alias in node.names)  # `from tactile_manip import sim`
    return names


def _sim_imports(folder: str, *, skip: str | None = None) -> dict[str, list[str]]:
    """{module path: the tactile_manip.sim modules it imports} under ``folder``, those under ``skip`` left out."""
    offenders = {}
    for path in sorted((PACKAGE / folder).rglob("*.py")):
        where = path.relative_to(PACKAGE).as_posix()
        found = sorted(n for n in _imported_modules(path) if n.split(".")[:2] == ["tactile_manip", "sim"])
        if found and not (skip and where.startswith(skip)):
            offenders[where] = found
    return offenders


def test_sensors_import_nothing_from_the_simulator():
    """Chip specs come from the core (tactile_manip.chips); only the simulated sensor's package imports it."""
    assert _sim_imports("sensors", skip=SIMULATED) == {}


def test_perception_imports_nothing_from_the_simulator():
    assert _sim_imports("perception") == {}


def test_the_import_scan_sees_the_simulator_driven_modules():
    """The scan itself works: the simulated sensor does import the simulator."""
    found = _sim_imports("sensors")
    assert {"sensors/simulated/sensor.py", "sensors/simulated/emulator.py", "sensors/simulated/contacts.py"} <= set(found)


def test_drivers_and_perception_load_no_simulator_module():
    code = ("import json, sys\nimport tactile_manip.sensors, tactile_manip.sensors.serial_sensor, "
            "tactile_manip.sensors.replay, tactile_manip.sensors.recording, tactile_manip.wire.anyskin, "
            "tactile_manip.perception, tactile_manip.perception.reconstruct\n"
            "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[:2] == ['tactile_manip', 'sim'])))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []


def _layer_imports(folder: str, layers: tuple[str, ...]) -> dict[str, list[str]]:
    """The modules of ``folder`` (anywhere in each file) that import one of ``layers`` (folders of the package)."""
    offenders = {}
    for path in sorted((PACKAGE / folder).rglob("*.py")):
        found = sorted(n for n in _imported_modules(path)
                       if n.split(".")[:2] in [["tactile_manip", layer] for layer in layers])
        if found:
            offenders[path.relative_to(PACKAGE).as_posix()] = found
    return offenders


def test_data_imports_nothing_from_the_sensors():
    """The data layer reads recordings through tactile_manip.logs, never through the sensors layer above it."""
    assert _layer_imports("data", ("sensors",)) == {}


@pytest.mark.parametrize("folder", ["wire", "logs"])
def test_wire_formats_and_logs_import_no_upper_layer(folder):
    assert _layer_imports(folder, ABOVE_THE_FORMATS) == {}


def test_the_layer_scan_sees_imports_inside_functions():
    """The scan itself works: the sensors' recorder imports the log format, and the data layer names
    tactile_manip.logs inside a function (read_reading_stream)."""
    assert "sensors/recording.py" in _layer_imports("sensors", ("logs",))
    assert "data/streams.py" in _layer_imports("data", ("logs",))


def test_data_reads_a_recording_without_loading_the_sensors(tmp_path):
    """At run time too: writing a recording with the log format and reading it through the data layer loads no
    module of tactile_manip.sensors."""
    path = tmp_path / "idle.tmrec"
    code = ("import json, sys\nimport numpy as np\n"
            "from tactile_manip.chips import MLX90393\n"
            "from tactile_manip.data.streams import read_reading_stream\n"
            "from tactile_manip.logs.recording import RecordingWriter\n"
            "from tactile_manip.wire.protocol import encode_frame\n"
            "chip = {'lsb_xy_ut': MLX90393.lsb_xy_ut, 'lsb_z_ut': MLX90393.lsb_z_ut, "
            "'saturation_counts': MLX90393.saturation_counts}\n"
            f"with RecordingWriter({str(path)!r}, {{'source': 'test', 'chip': chip}}) as out:\n"
            "    for k in range(3):\n"
            "        wire = encode_frame(np.full((4, 4, 3), k, np.int16), seq=k, t_mcu_us=8000 * k)\n"
            "        out.write_frame(k / 125, wire)\n"
            f"t, values, info = read_reading_stream({str(path)!r})\n"
            "assert values.shape == (3, 4, 4, 3) and info['frames'] == 3, (values.shape, info)\n"
            "print(json.dumps(sorted(m for m in sys.modules if m.split('.')[:2] == ['tactile_manip', 'sensors'])))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []


def test_perception_imports_nothing_from_evaluation():
    """The runtime (readings -> estimates) never depends on the code that scores it."""
    assert _layer_imports("perception", ("evaluation",)) == {}


def test_perception_loads_no_evaluation_module():
    code = ("import tactile_manip.perception, tactile_manip.perception.reconstruct, "
            "tactile_manip.perception.pose, tactile_manip.perception.estimator, tactile_manip.perception.contact, "
            "tactile_manip.perception.tactile_estimator, tactile_manip.perception.confidence, "
            "tactile_manip.perception.symmetry, tactile_manip.perception.angle_head")
    assert _modules_after(code, "m.split('.')[:2] == ['tactile_manip', 'evaluation']") == []


def _is_alias(path: Path) -> bool:
    """Whether a module only stands in for another: it rebinds ``sys.modules[__name__]``, or all it holds is
    imports of other tactile_manip modules (and ``__all__``) with nothing defined."""
    tree = ast.parse(path.read_text(), filename=str(path))
    body = [n for n in tree.body if not (isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant))]
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Subscript) and "sys.modules" in ast.unparse(t)
                                                for t in node.targets):
            return True
    imports = [n for n in body if isinstance(n, (ast.Import, ast.ImportFrom))]
    rest = [n for n in body if n not in imports and not (isinstance(n, ast.Assign)
                                                        and ast.unparse(n.targets[0]) == "__all__")
            and not (isinstance(n, ast.ImportFrom) and n.module == "__future__")]
    return bool(imports) and not rest and all(isinstance(n, ast.ImportFrom) and (n.module or "").startswith(
        "tactile_manip") for n in imports)


def test_no_module_is_an_alias_of_another():
    """Every module of the package holds code of its own (packages' __init__ files, which name their public API,
    aside): no module stands at an old path for one that moved."""
    offenders = [path.relative_to(PACKAGE).as_posix() for path in sorted(PACKAGE.rglob("*.py"))
                 if path.name != "__init__.py" and _is_alias(path)]
    assert offenders == []


def test_the_alias_scan_sees_an_alias(tmp_path):
    (tmp_path / "moved.py").write_text("import sys\nfrom tactile_manip import wire as _w\nsys.modules[__name__] = _w\n")
    (tmp_path / "names.py").write_text('"""doc"""\nfrom tactile_manip.wire import make_decoder\n'
                                       '__all__ = ["make_decoder"]\n')
    (tmp_path / "real.py").write_text("from tactile_manip.wire import make_decoder\n\ndef f():\n    return 1\n")
    assert [_is_alias(tmp_path / n) for n in ("moved.py", "names.py", "real.py")] == [True, True, False]


# Every module of the package by layer, lowest first; a module imports only its own layer's and lower ones'
# (docs/design.md, Layers). The modules at the package's top (types, errors, checks, ...) are the core.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("types", "errors", "checks", "config", "version", "extras", "outputs", "progress", "lifeline", "chips",
     "shipped", "plots", "__init__"),
    ("wire",), ("boards",), ("logs",), ("data",), ("sim",), ("sensors",), ("perception", "robot"),
    ("evaluation", "collection"), ("learning", "behaviours"), ("trials",), ("cluster", "interop", "bench"),
    ("commands",), ("cli",), ("__main__",))
RANK = {name: rank for rank, names in enumerate(LAYERS) for name in names}


def _against_the_layers(package: Path) -> list[str]:
    """``module -> imported module`` for every import (at any depth of a file) of a higher layer."""
    found = []
    for path in sorted(package.rglob("*.py")):
        here = path.relative_to(package).with_suffix("").parts[0]
        for name in sorted(_imported_modules(path, package)):
            parts = name.split(".")
            if parts[0] == "tactile_manip" and len(parts) > 1 and parts[1] != here \
                    and RANK.get(parts[1], -1) > RANK[here]:
                found.append(f"{path.relative_to(package).as_posix()} -> {name}")
    return found


def test_every_top_level_module_has_a_layer():
    names = {p.stem if p.is_file() else p.name for p in PACKAGE.iterdir()
             if (p.suffix == ".py" or (p / "__init__.py").is_file())}
    assert names - set(RANK) == set()


def test_no_import_runs_against_the_layers():
    assert _against_the_layers(PACKAGE) == []


def test_the_layer_scan_sees_an_import_of_a_higher_layer(tmp_path):
    (tmp_path / "sensors").mkdir()
    (tmp_path / "sensors" / "x.py").write_text("def f():\n    from tactile_manip.cli import main\n")
    (tmp_path / "commands").mkdir()
    (tmp_path / "commands" / "y.py").write_text("from tactile_manip.sensors import x\n")
    assert _against_the_layers(tmp_path) == ["sensors/x.py -> tactile_manip.cli",
                                             "sensors/x.py -> tactile_manip.cli.main"]
