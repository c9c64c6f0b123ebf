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

# the modules that moved from perception/ to evaluation/: the old name -> the new one. The old names stay
# importable for users (each file is an alias of the new module); no code of the repository imports them.
MOVED_TO_EVALUATION = {"evaluation": "images", "contact_evaluation": "contact", "contact_baselines": "contact_baselines",
                       "metrics": "metrics", "pose_reference": "pose_reference"}
ALIASES = tuple(f"perception/{old}.py" for old in MOVED_TO_EVALUATION)
# the modules that moved into learning/'s folder per model: the old name -> the new one, kept importable the same way
MOVED_IN_LEARNING = {"model": "cvae.model", "train": "cvae.train", "export": "cvae.export", "eager": "cvae.eager",
                     "data": "cvae.data", "angle_model": "angle_head.model", "angle_train": "angle_head.train",
                     "angle_export": "angle_head.export", "contact_model": "contact.model",
                     "contact_train": "contact.train", "contact_export": "contact.export",
                     "fewlabel": "contact.fewlabel"}
LEARNING_ALIASES = tuple(f"learning/{old}.py" for old in MOVED_IN_LEARNING)
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
    "import tactile_manip.perception.contact, tactile_manip.perception.contact_pose",
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
    "import tactile_manip.learning.kinds, tactile_manip.learning.cli, tactile_manip.learning.cvae.cli, "
    "tactile_manip.learning.angle_head.cli, tactile_manip.learning.contact.cli",
    # the CLI parser imports every command module, and `--help` must stay fast
    "import tactile_manip.cli; tactile_manip.cli.build_parser()",
])
def test_import_pulls_in_no_heavy_package(code):
    assert _heavy_modules_after(code) == []


def test_probe_sees_a_heavy_import():
    """The probe itself works: an import of matplotlib (a core dependency) is reported."""
    assert _heavy_modules_after("import tactile_manip.plots; tactile_manip.plots._pyplot()") == ["matplotlib"]


def _imported_modules(path: Path) -> set[str]:
    """Every module ``path`` imports, anywhere in the file (also inside functions), as dotted absolute names."""
    package = ".".join(("tactile_manip", *path.relative_to(PACKAGE).parent.parts))
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
            "tactile_manip.sensors.replay, tactile_manip.sensors.recording, tactile_manip.sensors.wire.anyskin, "
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
    """The runtime (readings -> estimates) never depends on the code that scores it; only the alias files left at
    the old module paths import tactile_manip.evaluation."""
    found = _layer_imports("perception", ("evaluation",))
    assert {where: names for where, names in found.items() if where not in ALIASES} == {}


def test_the_evaluation_scan_sees_the_aliases():
    """The scan itself works: each alias file at an old perception path imports its module of evaluation."""
    found = _layer_imports("perception", ("evaluation",))
    for old, new in MOVED_TO_EVALUATION.items():
        assert f"tactile_manip.evaluation.{new}" in found[f"perception/{old}.py"]


def test_perception_loads_no_evaluation_module():
    code = ("import tactile_manip.perception, tactile_manip.perception.reconstruct, "
            "tactile_manip.perception.pose, tactile_manip.perception.estimator, tactile_manip.perception.contact, "
            "tactile_manip.perception.contact_pose, tactile_manip.perception.confidence, "
            "tactile_manip.perception.symmetry, tactile_manip.perception.angle_head")
    assert _modules_after(code, "m.split('.')[:2] == ['tactile_manip', 'evaluation']") == []


MOVED = {**{f"perception.{old}": f"evaluation.{new}" for old, new in MOVED_TO_EVALUATION.items()},
         **{f"learning.{old}": f"learning.{new}" for old, new in MOVED_IN_LEARNING.items()}}


def test_old_module_paths_stay_importable_as_the_moved_modules():
    """A user's `from tactile_manip.perception.<old> import ...` (or `learning.<old>`) gets the very module that
    moved (to evaluation/, or into the model's folder), as attribute, import and import_module: one fresh
    interpreter for every old path."""
    checks = [f"import tactile_manip.{old} as alias\nimport tactile_manip.{new} as moved\n"
              f"assert alias is moved, {old!r}\n"
              f"import tactile_manip.{old.split('.')[0]} as package\n"
              f"assert package.{old.split('.')[1]} is moved, {old!r}\n"
              f"assert importlib.import_module('tactile_manip.{old}') is moved, {old!r}\n"
              for old, new in sorted(MOVED.items())]
    code = "import importlib\n" + "".join(checks)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert len(MOVED) >= 15 and done.returncode == 0, done.stderr


def _absolute_imports(path: Path) -> set[str]:
    """Every module a script outside the package imports by its absolute name, as dotted names."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def test_no_code_imports_through_the_aliases():
    """The old perception and learning paths are for users: the package, tests, benchmarks, tasks, examples and
    experiments import the moved modules by their new names."""
    old_names = ({f"tactile_manip.perception.{old}" for old in MOVED_TO_EVALUATION}
                 | {f"tactile_manip.learning.{old}" for old in MOVED_IN_LEARNING})
    offenders = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        where = path.relative_to(PACKAGE).as_posix()
        if where not in ALIASES + LEARNING_ALIASES and _imported_modules(path) & old_names:
            offenders[f"tactile_manip/{where}"] = sorted(_imported_modules(path) & old_names)
    for folder in ("tests", "benchmarks", "tasks", "examples", "experiments"):
        for path in sorted((REPOSITORY / folder).rglob("*.py")):
            if _absolute_imports(path) & old_names:
                offenders[path.relative_to(REPOSITORY).as_posix()] = sorted(_absolute_imports(path) & old_names)
    assert offenders == {}
