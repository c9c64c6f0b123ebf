"""What the report measures: methods (baselines and exported models) times runtimes, as buildable candidates.

A *method* is a way to turn a reading into a depth image (``bilinear``, a model file, a model averaged over
the sensor's symmetries). A *candidate* is a method on one runtime: numpy for the baselines; for a model,
onnxruntime with 1 thread and with all threads, onnxruntime on a dynamically int8-quantised copy, and torch
eager from the training checkpoint. A model file that is missing is skipped with a note, never an error.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tactile_manip.bench.machine import usable_cores
from tactile_manip.perception import one_reading
from tactile_manip.perception.reconstruct import Reconstructor, load_reconstructor, read_metadata
from tactile_manip.trials.scene import MethodSpec

RUNTIMES = ("ort-1", "ort-all", "ort-int8", "torch")
BASELINE_NAMES = ("bilinear", "bicubic")


@dataclass(frozen=True)
class ModelEntry:
    """An exported model to measure.

    Attributes:
        name: method name in the report (a word: letters, digits, ``_`` or ``-``).
        path: the ``.onnx`` file.
        checkpoint: its training checkpoint, for the torch-eager reference (None: no torch row).
        symmetrized: also measure it averaged over the sensor's symmetries, as method ``<name>_sym``.
        untrained_preset: when ``path`` is missing, export an untrained model of this preset (or training
            config ``.toml``) instead (latency only; its accuracy is reported as "n/a (untrained)").
        runtimes: the only runtimes to measure it on (None: every runtime asked for).
    """

    name: str
    path: Path
    checkpoint: Path | None = None
    symmetrized: bool = False
    untrained_preset: str | None = None
    runtimes: tuple[str, ...] | None = None


SHIPPED_MODEL = "models/supermag.onnx"  # the default model: the robust image graphs with an angle head inside


def default_models(root: str | Path = ".") -> list[ModelEntry]:
    """The default model (``supermag``: its image graphs and angle head on onnxruntime, one pass and averaged over
    the sensor's symmetries; no torch row, the checkpoint holds the image decoder only), path under ``root``.

    Other models come from candidates files (:func:`candidates_file`) and ``--model``."""
    return [ModelEntry("supermag", Path(root) / SHIPPED_MODEL, symmetrized=True)]


def candidates_file(path: str | Path, root: str | Path = ".", models: list[ModelEntry] | None = None
                    ) -> list[ModelEntry]:
    """``models`` (default: none) and the models a candidates file names, paths under ``root``.

    The file (TOML) holds ``[checkpoints]``,
    ``NAME = "RUN/best.pt"``: the torch-eager checkpoint of a model already in ``models``; ``[[model]]`` tables
    (``name``, ``path``, optional ``checkpoint``, ``untrained``: a preset or training config exported untrained
    when ``path`` is missing, ``runtimes``, ``symmetrized``); and ``[[runs]]`` tables: every training config
    matching the glob ``configs`` as ``runs/<stem>/model.onnx`` named ``<stem><suffix>``, on one thread
    (``untrained = true``: exported untrained when not trained; ``unless_recipe_of``: a config whose values are
    that file's is left out).

    Raises:
        ConfigError: the file is missing, not TOML, or holds an unknown table or key.
    """
    from tactile_manip.config import tomllib
    from tactile_manip.errors import ConfigError

    path, r = Path(path), Path(root)
    try:
        doc = tomllib.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise ConfigError(f"{path}: cannot read the bench candidates ({e})") from None

    def check(table: dict, allowed: set[str], where: str) -> None:
        unknown = sorted(set(table) - allowed)
        if unknown:
            raise ConfigError(f"{path}: unknown key(s) {', '.join(unknown)} in {where}; known: "
                              f"{', '.join(sorted(allowed))}")

    check(doc, {"checkpoints", "model", "runs"}, "the file")
    entries = list(models or [])
    names = {e.name for e in entries}
    for name, checkpoint in doc.get("checkpoints", {}).items():
        if name not in names:
            raise ConfigError(f"{path}: [checkpoints] names {name!r}, not one of the models {sorted(names)}")
        entries = [dataclasses.replace(e, checkpoint=r / checkpoint) if e.name == name else e for e in entries]
    for i, m in enumerate(doc.get("model", [])):
        check(m, {"name", "path", "checkpoint", "untrained", "runtimes", "symmetrized"}, f"[[model]] {i + 1}")
        if "name" not in m or "path" not in m:
            raise ConfigError(f"{path}: [[model]] {i + 1} needs a name and a path")
        entries.append(ModelEntry(m["name"], r / m["path"], r / m["checkpoint"] if "checkpoint" in m else None,
                                  symmetrized=bool(m.get("symmetrized", False)), untrained_preset=m.get("untrained"),
                                  runtimes=tuple(m["runtimes"]) if "runtimes" in m else None))
    for i, group in enumerate(doc.get("runs", [])):
        check(group, {"configs", "suffix", "untrained", "unless_recipe_of"}, f"[[runs]] {i + 1}")
        if "configs" not in group:
            raise ConfigError(f"{path}: [[runs]] {i + 1} needs configs, a glob of training configs")
        same = r / group["unless_recipe_of"] if "unless_recipe_of" in group else None
        recipe = _recipe(same) if same is not None and same.is_file() else None
        for c in sorted(r.glob(group["configs"])):
            if recipe is not None and _recipe(c) == recipe:
                continue
            run = r / "runs" / c.stem
            entries.append(ModelEntry(f"{c.stem}{group.get('suffix', '')}", run / "model.onnx", run / "best.pt",
                                      untrained_preset=str(c) if group.get("untrained") else None,
                                      runtimes=("ort-1",)))
    return entries


def _recipe(path: Path) -> dict:
    """A training config's values (its comments may differ from the copy shipped beside the model)."""
    from tactile_manip.config import tomllib

    with path.open("rb") as f:
        return tomllib.load(f)


def parse_model_spec(spec: str) -> ModelEntry:
    """``NAME=PATH.onnx`` -> a :class:`ModelEntry` (its checkpoint: ``best.pt`` beside the file, if there)."""
    name, sep, path = spec.partition("=")
    if not sep or not name or not path:
        raise ValueError(f"--model must be NAME=PATH, got {spec!r}")
    MethodSpec(name, path)  # validates the name as the trials log needs it
    checkpoint = Path(path).with_name("best.pt")
    return ModelEntry(name, Path(path), checkpoint if checkpoint.is_file() else None)


@dataclass
class Candidate:
    """One method on one runtime.

    ``build(threads)`` makes the reconstructor; the timings use ``threads``, the accuracy passes may use
    more (same outputs, checked). ``accuracy_key`` groups candidates that run the same numbers (the same
    weights in fp32 on onnxruntime with any thread count, or in torch): accuracy is computed once per key
    and shared once the outputs are checked to agree. ``trial_spec`` is the trials command's view of the
    method (None: run trials with an estimator from ``build``).
    """

    method: str
    runtime: str
    build: Callable[[int], Reconstructor]
    accuracy_key: str
    threads: int = 1
    accuracy_threads: int | None = None
    parameters: int | None = None
    file_mb: float | None = None
    path: str | None = None
    training: str = ""
    untrained: bool = False
    trial_spec: MethodSpec | None = None
    notes: list[str] = field(default_factory=list)


def baseline_candidates(names: tuple[str, ...] = BASELINE_NAMES) -> list[Candidate]:
    """The interpolation baselines at 200x200 (the shipped fit, as ``tactile-manip evaluate`` fits them)."""
    return [Candidate(n, "numpy", (lambda threads, n=n: load_reconstructor(n)), accuracy_key=n, parameters=2,
                      training="linear fit (AK + R train split)", trial_spec=MethodSpec(n, n)) for n in names]


def model_candidates(entry: ModelEntry, workdir: Path, *, runtimes: tuple[str, ...] = RUNTIMES,
                     notes: list[str]) -> list[Candidate]:
    """Candidates of one model on each runtime in ``runtimes``; what cannot run is skipped into ``notes``."""
    path, untrained = entry.path, False
    if entry.runtimes is not None:
        runtimes = tuple(r for r in runtimes if r in entry.runtimes)
    if not runtimes:
        return []
    if not path.is_file():
        if entry.untrained_preset is None:
            notes.append(f"{entry.name}: skipped, {path} not found (train it and `tactile-manip export` it)")
            return []
        try:
            from tactile_manip.learning.cvae.eager import export_untrained
        except ImportError:
            notes.append(f"{entry.name}: skipped, {path} not found and torch is not installed to export an "
                         "untrained one for latency")
            return []
        path, untrained = export_untrained(entry.untrained_preset, workdir / "untrained"), True
        entry = dataclasses.replace(entry, checkpoint=path.with_suffix(".pt"))  # torch runs the same weights
        notes.append(f"{entry.name}: {entry.path} not found; an untrained {entry.untrained_preset} model was "
                     "exported for latency only")
    meta = read_metadata(path)
    base = {"parameters": meta.get("parameters"), "training": "untrained" if untrained else training_note(path, meta),
            "untrained": untrained}
    methods = [(entry.name, False)] + ([(f"{entry.name}_sym", True)] if entry.symmetrized else [])
    int8 = _int8_copy(path, workdir, entry.name, notes) if "ort-int8" in runtimes else None
    out = []
    for method, sym in methods:
        for runtime in runtimes:
            cand = _runtime_candidate(entry, method, sym, runtime, path, int8, notes)
            if cand is not None:
                cand.parameters, cand.training, cand.untrained = base["parameters"], base["training"], untrained
                out.append(cand)
    return out


def _runtime_candidate(entry: ModelEntry, method: str, sym: bool, runtime: str, path: Path, int8: Path | None,
                       notes: list[str]) -> Candidate | None:
    def wrap(make: Callable[[int], Reconstructor]) -> Callable[[int], Reconstructor]:
        if not sym:
            return make
        from tactile_manip.perception.symmetry import SymmetrizedReconstructor

        return lambda threads: SymmetrizedReconstructor(make(threads))

    fp32 = f"{method}:fp32"
    if runtime in ("ort-1", "ort-all"):
        threads = 1 if runtime == "ort-1" else usable_cores()
        if runtime == "ort-all" and threads == 1:
            return None  # one usable core: the same as ort-1
        label = f"onnxruntime {threads} thread" + ("s" if threads > 1 else "")
        load = wrap(lambda n: load_reconstructor(path, threads=n, image_symmetry="stored"))  # the file's images
        return Candidate(method, label, load, fp32,
                         threads=threads, accuracy_threads=usable_cores(), file_mb=_mb(path), path=str(path),
                         trial_spec=MethodSpec(method, str(path), symmetrize=sym))
    if runtime == "ort-int8":
        if int8 is None:
            return None
        load = wrap(lambda n: load_reconstructor(int8, threads=n, image_symmetry="stored"))
        return Candidate(method, "onnxruntime int8 1 thread", load,
                         f"{method}:int8", accuracy_threads=usable_cores(), file_mb=_mb(int8), path=str(int8),
                         trial_spec=MethodSpec(method, str(int8), symmetrize=sym))
    if runtime == "torch":
        if sym:
            return None  # the reference is the model itself; 8 torch passes per reading would add nothing
        if entry.checkpoint is None or not entry.checkpoint.is_file():
            notes.append(f"{entry.name}: torch eager n/a (no checkpoint {entry.checkpoint or 'beside the file'})")
            return None
        try:
            from tactile_manip.learning.cvae.eager import TorchReconstructor
        except ImportError:
            notes.append(f"{entry.name}: torch eager n/a (torch is not installed)")
            return None
        pixel_mm = float(read_metadata(path)["output"]["pixel_mm"])
        ckpt = entry.checkpoint
        return Candidate(method, "torch eager 1 thread",
                         lambda n: TorchReconstructor(ckpt, threads=n, pixel_mm=pixel_mm), fp32, file_mb=_mb(ckpt),
                         path=str(ckpt))
    raise ValueError(f"unknown runtime {runtime!r}; known: {', '.join(RUNTIMES)}")


def _int8_copy(path: Path, workdir: Path, name: str, notes: list[str]) -> Path | None:
    """Dynamic int8 quantisation of ``path`` (weights int8, activations quantised at run time) into
    ``workdir``; None with a note when it fails."""
    out = workdir / "int8" / f"{name}.int8.onnx"
    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        from onnxruntime.quantization import QuantType, quantize_dynamic
    except ImportError as e:
        notes.append(f"{name}: int8 n/a (onnxruntime.quantization needs the onnx package: {e})")
        return None
    quiet = logging.getLogger()
    level = quiet.level
    quiet.setLevel(logging.ERROR)  # the quantiser logs a pre-processing advice on every call
    try:
        quantize_dynamic(str(path), str(out), weight_type=QuantType.QInt8)
        _drop_one_reading_graph(out)
        read_metadata(out)  # the metadata must survive, or the reconstructor cannot load it
    except Exception as e:  # noqa: BLE001 - the quantiser raises many types; the report records why
        notes.append(f"{name}: int8 quantisation failed ({type(e).__name__}: {e})")
        return None
    finally:
        quiet.setLevel(level)
    notes.append(f"{name}: int8 {_where_int8_applies(out)}")
    return out


def _drop_one_reading_graph(path: Path) -> None:
    """Remove the float one-reading graph the quantiser copied with the metadata: the int8 rows time the
    quantised main graph (the one-reading graph would neither match it nor be int8)."""
    import onnx

    proto = onnx.load(str(path))
    one_reading.remove_from(proto)
    onnx.save(proto, str(path))


def _where_int8_applies(path: Path) -> str:
    """Which layers the quantiser turned into integer ops, and which compute layers stayed float."""
    from collections import Counter

    import onnx

    ops = Counter(n.op_type for n in onnx.load(str(path), load_external_data=False).graph.node)
    done = {"ConvInteger": "Conv", "MatMulInteger": "Gemm/MatMul"}
    applied = ", ".join(f"{ops[q]} {f}" for q, f in done.items() if ops[q]) or "no layer"
    left = ", ".join(f"{ops[o]} {o}" for o in ("Conv", "ConvTranspose", "Gemm", "MatMul") if ops[o]) or "none"
    return f"applies to {applied} (integer kernels); float compute layers left: {left}"


def training_note(path: Path, meta: dict[str, Any]) -> str:
    """How the model was trained, from the run's history next to the file (``history.json`` or
    ``<stem>.history.json``), else from the training config in its metadata: "28 epochs", "4 optimizer steps"."""
    for hist in (path.with_name(path.stem + ".history.json"), path.with_name("history.json")):
        if hist.is_file():
            try:
                doc = json.loads(hist.read_text())
                last = doc["history"][-1]
            except (ValueError, KeyError, IndexError):
                continue
            if float(last.get("epoch_fraction", 1.0)) < 1.0:
                steps = int(last.get("batches", 0))
                return f"{steps} optimizer steps ({float(last['epoch_fraction']):.0%} of an epoch)"
            return _epochs(int(doc.get("epochs_run", last.get("epoch", 0))))
    epochs = meta.get("train_config", {}).get("epochs")
    return f"{_epochs(int(epochs))} (config)" if epochs else "unknown"


def _epochs(n: int) -> str:
    return f"{n} epoch" + ("" if n == 1 else "s")


def _mb(path: Path) -> float:
    return round(os.path.getsize(path) / 1e6, 2)
