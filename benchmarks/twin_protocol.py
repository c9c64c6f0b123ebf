"""The twin's protocol on the eFlesh runs: forward fidelity, its limit, and contact from the twin against K labels.

    python -m benchmarks.twin_protocol                                   # the dev runs, every section
    python -m benchmarks.twin_protocol --runs /path/to/runs --sections forward limit
    python -m benchmarks.twin_protocol --sections contact --k 0 25 --work /tmp/twin_cache
    python -m benchmarks.twin_protocol --kind spatial --sections zero_label --board LAYOUT.toml --update

Per run, the chronological 80/20 split of ``tactile-manip import``: every fit (the board's, a smooth map's, a
contact model's) sees only the first 80 % of the run's rows; every score is on the last 20 %. Sections:

- ``forward``: the explained variance (:func:`benchmarks.twin_limits.explained_variance`, per channel and
  overall) of the test readings given the logged probe pose, for the shipped ``eflesh`` board file and for a board
  fitted by ``tactile-manip fit-board`` on the first 80 % (where the command exists), through ``tactile-manip
  simulate-log``; baseline-subtracted stream.
- ``zero_label`` (also run by ``forward``): ``fit-board`` without labels on each run's first 80 % (its readings
  alone), and on the spatial run the position RMSE of the test presses read backwards on that twin and refitted on
  a smooth model of the real field fitted on the first 80 %'s presses at their twin places (the raw read-back
  beside it), the pad frame's offset and best quarter turn fitted on them, beside the twin fitted with every label
  placed the same way. ``--board`` names the board file fitted and imported with (the template).
- ``limit``: the best explained variance any smooth map of the probe pose reaches on the same split (kNN and
  thin-plate RBF over x, y, z, hyper-parameters by cross-validation inside the first 80 %), raw and
  baseline-subtracted streams, with and without the run's elapsed time as a fourth coordinate (reported apart: a
  twin has no clock); and the bound of the zero-label goal: the position RMSE on the spatial run's test presses of
  the best smooth map (fitted with every label of the first 80 %) read backwards.
- ``contact``: per K (0, 10, 25, 100) and seed (0, 1), the contact model of ``configs/train/contact_twin.toml``
  (the twin's simulated presses label the unlabelled ones, the K labels correct them; ``train --prior``), the twin
  being ``fit-board`` without labels on the run's first 80 % whatever K (the twin's places, refitted on the real
  readings, start the few-label recipe's refit beside its maps; the labels say how much they weigh), beside
  kNN (k = 5) on the same K labels and today's few-label recipe (``configs/train/contact_fewlabel.toml``: its
  committed figures in docs/results/contact/fewlabel_k.json, the same runs, split and seeds, since a case takes it
  tens of minutes). With K = 0 no label is used at all (no states.csv in the twin's fit); the positions are in the
  board file's pad frame, so a 2-D offset and the best of the 8 quarter turns and mirror images of the axes are
  fitted on the test presses (as benchmarks/eflesh_zero_label.py). The same recipe with a smooth map of the pose as
  its twin (``--twins bound``; its places as read, ``twin_refine`` off) bounds what a perfect twin would give.

Writes docs/results/twin/twin_protocol.{json,md} and plots (``--out``). It measures; it asserts nothing. Run it
with ``nice``: a contact case trains an ensemble (about 2 minutes on two cores).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish
from benchmarks.twin_limits import choose_map, explained_variance, forward_limit, inverted_places, pose_grid

DEFAULT_RUNS = Path(os.environ.get("TACTILE_MANIP_EFLESH_DIR", Path(__file__).resolve().parents[2] / "shared"
                                   / "data" / "eflesh_dev"))
SPATIAL, NORMAL = "spatial", "normal"
CONTACT_Z_MM = 145.1  # the publishers count a spatial row as a press where z < this
LABELS = {SPATIAL: "time_s,x_mm,y_mm,z_mm", NORMAL: "time_s,x_mm,y_mm,z_mm,force_gf"}
CONTACT = {SPATIAL: (["--contact", f"z_mm < {CONTACT_Z_MM}", "--targets", "x_mm,y_mm"], "position_rmse_mm"),
           NORMAL: (["--missing", "-1", "--targets", "force_n"], "force_rmse_n")}
MANIFOLD = Path("docs/results/contact/fewlabel_k.json")
TEMPLATE = {"board": "eflesh"}  # the board file every run is imported with and fitted from (--board)
ORDER = ("twin", "bound", "manifold (committed)", "kNN")  # the contact table's columns
MADE_S: dict[str, float] = {}  # seconds each cached file took to make (fit, twin's presses), by path
FIT_ERRORS: dict[str, str] = {}  # fit-board's one-line refusal, by the path it would have written
NO_LABELS = "fitted, no labels"
TURNS = [np.array(m, float) for m in ([[1, 0], [0, 1]], [[0, -1], [1, 0]], [[-1, 0], [0, -1]], [[0, 1], [-1, 0]],
                                      [[1, 0], [0, -1]], [[-1, 0], [0, 1]], [[0, 1], [1, 0]], [[0, -1], [-1, 0]])]


def given_name() -> str:
    """How the tables name the board file as given (not fitted)."""
    return "eflesh (shipped)" if TEMPLATE["board"] == "eflesh" else f"{Path(TEMPLATE['board']).stem} (as given)"


def run_folders(runs: Path) -> dict[str, Path]:
    """The run folder of each kind (spatial, normal): the first ``spatial_*`` and ``normal_*`` under ``runs``."""
    found = {}
    for kind in (SPATIAL, NORMAL):
        hits = sorted(p for p in runs.glob(f"{kind}_*") if (p / "states.csv").is_file())
        if hits:
            found[kind] = hits[0]
    if not found:
        raise SystemExit(f"no spatial_* or normal_* run folders with states.csv under {runs}")
    return found


def cli(*args: str, quiet: bool = True) -> subprocess.CompletedProcess:
    """``tactile-manip ARGS`` in a subprocess; a failure ends the benchmark with the command's stderr."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "tactile_manip", *args], capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(f"tactile-manip {' '.join(args)} failed:\n{done.stderr[-2000:]}")
    if not quiet:
        print(f"  tactile-manip {args[0]}: {time.perf_counter() - start:.0f} s", flush=True)
    return done


def has_command(name: str) -> bool:
    return subprocess.run([sys.executable, "-m", "tactile_manip", name, "--help"], capture_output=True).returncode == 0


def imported(run: Path, kind: str, stream: str, work: Path, extra: list[str], tag: str) -> Any:
    """The run imported (``stream``: sensor or sensor_post_baselines) with ``extra`` flags, cached in ``work``."""
    from tactile_manip.data import load_dataset

    out = work / f"{run.name}_{stream}_{tag}.npz"
    if not out.is_file():
        cli("import", "--readings-csv", str(run / f"{stream}.csv"), "--labels-csv", str(run / "states.csv"),
            "--label-columns", LABELS[kind], *extra, "--board", TEMPLATE["board"], "--out", str(out))
    return load_dataset(out, images=False)


def pose_and_readings(data: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(N, 3) stage pose, (N, C) the varying reading channels, (N,) the run's elapsed share."""
    flat = data.readings.reshape(len(data), -1).astype(np.float64)
    live = flat.std(axis=0) > 0
    pose = np.stack([data.target(n) for n in ("x_mm", "y_mm", "z_mm")], axis=1).astype(np.float64)
    t = data.extra("time_s")
    return pose, flat[:, live], (t - t.min()) / max(np.ptp(t), 1e-9)


# -- sections ------------------------------------------------------------------------------------------------------

def section_limit(runs: dict[str, Path], work: Path) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for kind, run in runs.items():
        for stream in ("sensor_post_baselines", "sensor"):
            data = imported(run, kind, stream, work, ["--targets", "x_mm,y_mm,z_mm"], "pose")
            pose, y, share = pose_and_readings(data)
            train, test = data.indices("train"), data.indices("test")
            out[f"{kind}/{stream}"] = {"pose": forward_limit(pose, y, train, test),
                                       "pose_and_time": forward_limit(np.c_[pose, share], y, train, test,
                                                                      with_time=True)}
            print(f"limit {kind} {stream}: pose {out[f'{kind}/{stream}']['pose']['test_ev']:.3f}, with time "
                  f"{out[f'{kind}/{stream}']['pose_and_time']['test_ev']:.3f}", flush=True)
    if SPATIAL in runs:
        out["zero_label_bound"] = zero_label_bound(runs[SPATIAL], work)
    return out


def zero_label_bound(run: Path, work: Path) -> dict[str, Any]:
    """Position RMSE (mm) on the spatial run's test presses of the best smooth map of the pose, fitted with every
    label of the first 80 % and read backwards on a grid of poses (0.25 mm, 24 depths): what a twin as faithful
    as that map would place with zero labels."""
    data = imported(run, SPATIAL, "sensor_post_baselines", work, ["--targets", "x_mm,y_mm,z_mm"], "pose")
    pose, y, _ = pose_and_readings(data)
    train, test = data.indices("train"), data.indices("test")
    test = test[pose[test, 2] < CONTACT_Z_MM]
    fit = choose_map("thin-plate RBF", pose[train], y[train])
    grid = pose_grid(pose[train], step_mm=0.25)
    placed = inverted_places(fit, grid[grid[:, 2] < CONTACT_Z_MM], y[test])
    return {"map": fit.name, "params": {k: float(v) for k, v in fit.params.items() if k != "varies"},
            "test_presses": int(len(test)),
            "position_rmse_mm": float(np.sqrt(np.mean(np.sum((placed[:, :2] - pose[test, :2]) ** 2, axis=1))))}


def section_forward(runs: dict[str, Path], work: Path) -> dict[str, Any]:
    """EV of each run's test readings given the logged pose, through ``simulate-log``: the shipped board file, and
    boards fitted by ``fit-board`` on the run's first 80 % with every label of it and with none."""
    if not has_command("simulate-log"):
        return {"note": "tactile-manip simulate-log is not in this checkout; no board scored"}
    out: dict[str, Any] = {}
    for kind, run in runs.items():
        data = imported(run, kind, "sensor_post_baselines", work, ["--targets", "x_mm,y_mm,z_mm"], "pose")
        measured = data.readings.reshape(len(data), -1).astype(np.float64)
        live, test = measured.std(axis=0) > 0, data.indices("test")
        boards = {given_name(): TEMPLATE["board"], "fitted, every label of the first 80 %": fit_board(
            run, kind, work, "all", 0)}
        for name, board in boards.items():
            if board is None:
                fits = [e for p, e in FIT_ERRORS.items() if run.name in p and ("nolabels" in p) == ("no" in name)]
                out[f"{name}/{kind}"] = {"note": fits[-1] if fits else "no fit"}
                continue
            sim = work / f"simlog_{Path(str(board)).stem}_{run.name}.npz"
            done = subprocess.run([sys.executable, "-m", "tactile_manip", "simulate-log", "--board", str(board),
                                   "--labels", str(run / "states.csv"), "--label-columns", LABELS[kind],
                                   "--readings", str(run / "sensor_post_baselines.csv"), "--out", str(sim),
                                   "--force"], capture_output=True, text=True)
            if done.returncode:
                out[f"{name}/{kind}"] = {"note": done.stderr.strip().splitlines()[-1]}
                print(f"forward {name} {kind}: {out[f'{name}/{kind}']['note']}", flush=True)
                continue
            with np.load(sim, allow_pickle=False) as z:
                pred = z["readings"].reshape(len(data), -1).astype(np.float64)
            per_channel, overall = explained_variance(pred[test][:, live], measured[test][:, live])
            out[f"{name}/{kind}"] = {"test_ev": overall, "test_ev_per_channel": per_channel.tolist(),
                                     "fit_seconds": MADE_S.get(str(board))}
            print(f"forward {name} {kind}: EV {overall:.3f}", flush=True)
        out.update(section_zero_label({kind: run}, work))
    return out


def section_zero_label(runs: dict[str, Path], work: Path) -> dict[str, Any]:
    """The forward table's "fitted, no labels" rows: ``fit-board`` without labels on each run's first 80 % (its
    readings alone: no states.csv), and on the spatial run the position RMSE (mm) of its test presses read backwards
    on the twin (:func:`~tactile_manip.learning.contact.twin_prior.twin_targets` over a bank of the twin's presses
    all over the pad), the pad frame's offset and the best quarter turn fitted on those presses (and of the 8 quarter
    turns and mirror images). A twin without labels has no rig frame, so no forward EV at logged poses."""
    from tactile_manip.boards import load_board

    out: dict[str, Any] = {}
    for kind, run in runs.items():
        fitted = fit_board(run, kind, work, None, 0)
        if fitted is None:
            fits = [e for p, e in FIT_ERRORS.items() if run.name in p and "nolabels" in p]
            out[f"{NO_LABELS}/{kind}"] = {"note": fits[-1] if fits else "no fit"}
            continue
        board = load_board(str(fitted))
        row: dict[str, Any] = {"fit_seconds": MADE_S.get(str(fitted)), "fit_stages": board.fit["stages"]}
        if kind == SPATIAL:  # the labels are read here only to score
            row.update(placed_backwards(board, run))
            bound = fit_board(run, kind, work, "all", 0)  # the same family fitted with every label: its bound
            if bound is not None:
                row["bound_every_label"] = placed_backwards(load_board(str(bound)), run)
            print(f"zero labels {kind}: {row['position_rmse_mm']:.2f} mm on {row['test_presses']} test presses "
                  f"(read backwards alone {row['read_backwards_position_rmse_mm']:.2f} mm)"
                  + (f" (every label: {row['bound_every_label']['position_rmse_mm']:.2f} mm)" if bound else ""),
                  flush=True)
        out[f"{NO_LABELS}/{kind}"] = row
    return out


def placed_backwards(board: Any, run: Path) -> dict[str, Any]:
    """The spatial run's presses read backwards on ``board``'s twin in its pad frame (no rig frame: a bank of the
    twin's presses over the pad, 0.5 mm apart, 16 depths), then refitted on a smooth model of the real field
    (:func:`~tactile_manip.learning.contact.twin_prior.refined_places`: its models fitted on the first 80 %'s
    presses alone, the test presses placed on them); the test presses scored, read backwards and refitted, after
    the best offset and quarter turn (and of the 8 quarter turns and mirror images) fitted on them. The labels are
    read only to score."""
    from tactile_manip.commands.twin_logs import probe_rows
    from tactile_manip.learning.contact.twin_prior import refined_places, twin_targets
    from tactile_manip.sim.twin import BoardTwin
    from tactile_manip.sim.twin_blind import NOMINAL_DEPTH_MM, pad_points

    rows = probe_rows(board, run / "sensor_post_baselines.csv", run / "states.csv", LABELS[SPATIAL].split(","), 0.8)
    assert rows.readings_ut is not None
    pressed = rows.stage_xyz_mm[:, 2] < CONTACT_Z_MM
    train, test = (np.flatnonzero((rows.split == part) & pressed) for part in ("train", "test"))
    both = np.r_[train, test]
    twin = BoardTwin(board)
    points = pad_points(board, 0.5)
    depths = np.geomspace(0.01, 1.6, 16) * (NOMINAL_DEPTH_MM if board.fit.get("labelled") == 0 else 6.0)
    where = np.repeat(points, len(depths), axis=0)
    placed = twin_targets(rows.readings_ut[both], twin.readings_at_pad_ut(where, np.tile(depths, len(points))), where)
    refined = refined_places(rows.readings_ut[both], placed, fitted=np.arange(len(both)) < len(train))
    true = rows.stage_xyz_mm[test, :2]
    read, fit = placed[len(train):], refined[len(train):]
    return {"test_presses": len(test), "train_presses": len(train),
            "position_rmse_mm": frame_rmse(fit, true, TURNS[:4]),
            "position_rmse_mm_with_mirrors": frame_rmse(fit, true, TURNS),
            "read_backwards_position_rmse_mm": frame_rmse(read, true, TURNS[:4]),
            "read_backwards_position_rmse_mm_with_mirrors": frame_rmse(read, true, TURNS)}


def frame_rmse(placed: np.ndarray, true: np.ndarray, turns: list[np.ndarray]) -> float:
    """2-D RMSE (mm) of ``placed`` against ``true`` (N, 2) after the best of ``turns`` and an offset
    (:func:`~tactile_manip.learning.contact.twin_prior.frame_rmse`)."""
    from tactile_manip.learning.contact import twin_prior

    return twin_prior.frame_rmse(placed, true, turns)


def fit_board(run: Path, kind: str, work: Path, k: int | str | None, seed: int) -> Path | None:
    """A board fitted by ``fit-board`` on the run's first 80 % (its readings, and K labels where ``k``; every label
    of them where ``k`` is ``"all"``), or None where the command is not in this checkout or fits nothing without
    labels."""
    if not has_command("fit-board"):
        return None
    out = work / f"fitted_{run.name}_{'nolabels' if k is None else f'k{k}_s{seed}'}.toml"
    if out.is_file():
        return out
    labels = [] if k is None else ["--labels", str(run / "states.csv"), "--label-columns", LABELS[kind],
                                   "--labelled", str(k), "--seed", str(seed)]
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "tactile_manip", "fit-board", "--board", TEMPLATE["board"], "--raw",
                           str(run / "sensor.csv"), "--subtracted", str(run / "sensor_post_baselines.csv"), *labels,
                           "--train-fraction", "0.8", "--out", str(out), "--quiet"], capture_output=True, text=True)
    if done.returncode:  # e.g. a fit from the readings alone, not in this checkout; the caller says so
        FIT_ERRORS[str(out)] = done.stderr.strip().splitlines()[-1] if done.stderr.strip() else f"rc {done.returncode}"
        print(f"  fit-board {run.name} K={k} seed {seed}: {FIT_ERRORS[str(out)]}", flush=True)
        return None
    MADE_S[str(out)] = time.perf_counter() - start
    print(f"  fit-board {run.name} K={k} seed {seed}: {MADE_S[str(out)]:.0f} s", flush=True)
    return out


def twin_bank(board: Path | str, work: Path, presses: int) -> Path:
    """The twin's simulated presses (``simulate --board``, a 6 mm sphere as the rig's probe), cached."""
    out = work / f"bank_{Path(str(board)).stem}_{presses}.npz"
    if not out.is_file():
        start = time.perf_counter()
        cli("simulate", "--board", str(board), "--presses", str(presses), "--tip", "sphere", "--tip-diameter-mm",
            "6", "--seed", "0", "--out", str(out), quiet=False)
        MADE_S[str(out)] = time.perf_counter() - start
    return out


def simlog_bank(board: Path, work: Path) -> Path:
    """The fitted twin's readings at a grid of stage poses over its pad (``simulate-log --grid``), as a dataset of
    presses whose targets are the poses (x_mm, y_mm, z_mm): ``train --prior``'s bank, in the board's rig frame."""
    out = work / f"bank_{board.stem}.npz"
    if out.is_file():
        return out
    start = time.perf_counter()
    cli("simulate-log", "--board", str(board), "--grid", "--out", str(out), "--force")
    MADE_S[str(out)] = time.perf_counter() - start
    return out


def map_twin_bank(run: Path, kind: str, work: Path) -> Path:
    """A bank of presses from the best smooth map of the pose (fitted with every label of the first 80 %): the
    twin a perfect fit would give, for the bound."""
    from tactile_manip.data import save_dataset

    from benchmarks.twin_limits import map_bank

    out = work / f"bank_map_{run.name}.npz"
    if out.is_file():
        return out
    extra = ["--targets", "x_mm,y_mm,z_mm,force_n", "--missing", "-1"] if kind == NORMAL else [
        "--targets", "x_mm,y_mm,z_mm"]
    data = imported(run, kind, "sensor_post_baselines", work, extra, "bank")
    pose, y, _ = pose_and_readings(data)
    train = data.indices("train")
    live = data.readings.reshape(len(data), -1).std(axis=0) > 0
    fit = choose_map("thin-plate RBF", pose[train], y[train])
    targets: dict[str, Any] = {"x_mm": lambda p: p[:, 0], "y_mm": lambda p: p[:, 1]}
    if kind == NORMAL:
        force = choose_map("kNN", pose[train], data.target("force_n")[train, None].astype(np.float64))
        targets = {"force_n": lambda p: force.predict(p)[:, 0]}
        grid = np.c_[np.full((400, 2), pose[train, :2].mean(axis=0)), np.linspace(pose[train, 2].min(),
                                                                                   pose[train, 2].max(), 400)]
    else:
        grid = pose_grid(pose[train], step_mm=0.5)
        grid = grid[grid[:, 2] < CONTACT_Z_MM]
    save_dataset(out, map_bank(fit, grid, live, data, targets=targets))
    return out


def contact_case(run: Path, kind: str, k: int, seed: int, bank: Path, work: Path, tag: str) -> dict[str, Any]:
    """One K and seed: import with K labels, train the twin recipe with ``bank`` as its prior, export, and score it
    and kNN on the same K labels on the test presses."""
    from tactile_manip.data import load_dataset
    from tactile_manip.evaluation.contact import model_predictions
    from tactile_manip.perception.contact import ContactEstimator

    flags, figure = CONTACT[kind]
    name = f"{run.name}_k{k}_s{seed}_{tag}"
    data_path = work / f"{run.name}_k{k}_s{seed}.npz"
    if not data_path.is_file():
        cli("import", "--readings-csv", str(run / "sensor_post_baselines.csv"), "--labels-csv",
            str(run / "states.csv"), "--label-columns", LABELS[kind], *flags, "--board", TEMPLATE["board"],
            "--labelled",
            str(k), "--seed", str(seed), "--out", str(data_path))
    done = work / f"{name}.seconds"  # a case trained by an earlier call on the same cache is read, not retrained
    if not (done.is_file() and (work / f"{name}.onnx").is_file()):
        start = time.perf_counter()
        config = twin_config(work, refit=tag != "map")
        cli("train", "--config", str(config), "--data", str(data_path), "--prior", str(bank),
            "--out", str(work / name), "--force", "--seed", str(seed), "--quiet")
        cli("export", "--checkpoint", str(work / name / "best.pt"), "--out", str(work / f"{name}.onnx"), "--force")
        done.write_text(f"{time.perf_counter() - start:.1f}\n")
    seconds = float(done.read_text())
    data = load_dataset(data_path, images=False)
    test = data.indices("test")
    names = list(data.target_names)
    true = np.stack([data.target(n) for n in names], axis=1)[test].astype(np.float64)
    pred, _ = model_predictions(ContactEstimator(work / f"{name}.onnx", press_check=False), data, test)
    out = {"twin": score(pred, true, names, fit_frame=(k == 0 and "x_mm" in names)), "train_seconds": seconds}
    if k >= 5:
        out["kNN"] = score(knn(data, names, test), true, names)
    history = json.loads((work / name / "history.json").read_text())
    out["labels"] = (history.get("pseudo_labels") or {}).get("methods")
    print(f"  {kind} K={k} seed {seed} ({tag}): twin {out['twin']:.3f}"
          + (f", kNN {out['kNN']:.3f}" if "kNN" in out else "") + f" ({seconds:.0f} s)", flush=True)
    return out


def twin_config(work: Path, *, refit: bool) -> Path:
    """``configs/train/contact_twin.toml``, or where not ``refit`` a copy of it in ``work`` with ``twin_refine``
    off: a smooth map of the pose as the twin (the bound) places presses closer than the field model it would be
    refitted on (on the spatial run with no label, 0.48 mm as read and 0.97 mm refitted)."""
    config = Path("configs/train/contact_twin.toml")
    if refit:
        return config
    text = config.read_text()
    if "twin_refine = true" not in text:
        raise SystemExit(f"{config} no longer sets twin_refine = true: the bound's copy cannot turn it off")
    out = work / "contact_twin_as_read.toml"
    out.write_text(text.replace("twin_refine = true", "twin_refine = false"))
    return out


def score(pred: np.ndarray, true: np.ndarray, names: list[str], *, fit_frame: bool = False) -> float:
    """2-D position RMSE (mm) where the targets are places (with ``fit_frame``, after the best quarter turn or
    mirror and offset fitted on these rows), else the first target's RMSE."""
    if "x_mm" in names and "y_mm" in names:
        p = pred[:, [names.index("x_mm"), names.index("y_mm")]]
        t = true[:, [names.index("x_mm"), names.index("y_mm")]]
        if fit_frame:
            return frame_rmse(p, t, TURNS)
        return float(np.sqrt(np.mean(np.sum((p - t) ** 2, axis=1))))
    return float(np.sqrt(np.mean((pred[:, 0] - true[:, 0]) ** 2)))


def knn(data: Any, names: list[str], test: np.ndarray) -> np.ndarray:
    """evaluate's kNN baseline (k = 5, standardised readings and targets) on the labelled training presses."""
    from tactile_manip.evaluation.contact_baselines import KNN_NEIGHBOURS, Standardiser, flat
    from sklearn.neighbors import KNeighborsRegressor

    train = data.indices("train")
    y = np.stack([data.target(n) for n in names], axis=1).astype(np.float64)
    xs, ys = Standardiser.fit(flat(data.readings[train])), Standardiser.fit(y[train])
    model = KNeighborsRegressor(n_neighbors=min(KNN_NEIGHBOURS, len(train)), weights="distance")
    model.fit(xs(flat(data.readings[train])), ys(y[train]))
    return ys.mean + ys.scale * model.predict(xs(flat(data.readings[test]))).reshape(len(test), -1)


def section_contact(runs: dict[str, Path], work: Path, ks: list[int], seeds: list[int], *, presses: int,
                    twins: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    manifold = json.loads(MANIFOLD.read_text())["runs"] if MANIFOLD.is_file() else {}
    for kind, run in runs.items():
        rows: dict[str, Any] = {}
        for k in ks:
            per_seed: dict[str, Any] = {}
            for seed in seeds[:1] if k == 0 else seeds:
                case: dict[str, Any] = {}
                if "twin" in twins:
                    # the twin fitted to the readings alone, whatever K: the labels bring its places into their
                    # frame (with the refit, it places presses closer than a twin fitted on the K labels)
                    fitted = fit_board(run, kind, work, None, 0)
                    if fitted and kind == NORMAL and k == 0:
                        break  # a twin of stage poses gives no force in newtons: the labels fit it (K > 0)
                    bank = (simlog_bank(fitted, work) if fitted
                            else twin_bank(TEMPLATE["board"], work, presses))
                    case = contact_case(run, kind, k, seed, bank, work, "twin")
                    case["board"] = "fitted, no labels" if fitted else given_name() + ", " + FIT_ERRORS.get(
                        str(work / f"fitted_{run.name}_nolabels.toml"), "")
                    case["seconds"] = {"fit": MADE_S.get(str(fitted)), "twin_presses": MADE_S.get(str(bank)),
                                       "train_and_export": case.pop("train_seconds")}
                if "bound" in twins:
                    bound = contact_case(run, kind, k, seed, map_twin_bank(run, kind, work), work, "map")
                    case["bound"] = bound["twin"]
                    case.setdefault("kNN", bound.get("kNN"))
                per_seed[str(seed)] = case
            methods = [m for m in ("twin", "kNN", "bound")
                       if per_seed and all(c.get(m) is not None for c in per_seed.values())]
            mean = {m: float(np.mean([c[m] for c in per_seed.values()])) for m in methods}
            committed = manifold.get(run.name, {}).get(str(k), {}).get("mean", {})
            if "ours" in committed:
                mean["manifold (committed)"] = committed["ours"]
            rows[str(k)] = {"per_seed": per_seed, "mean": mean}
        out[kind] = {"run": run.name, "figure": CONTACT[kind][1], "k": rows}
    return out


def merged_row(old: dict[str, Any], new: dict[str, Any]) -> dict[str, Any]:
    """A contact table row of a new call over the one it updates: the methods the new call did not run keep their
    figures (a K = 0 twin case leaves the bound's)."""
    seeds = dict(old.get("per_seed", {}))
    for seed, case in new.get("per_seed", {}).items():
        seeds[seed] = {**seeds.get(seed, {}), **case}
    return {**old, **new, "per_seed": seeds, "mean": {**old.get("mean", {}), **new.get("mean", {})}}


# -- report --------------------------------------------------------------------------------------------------------

def markdown(report: dict[str, Any]) -> str:
    lines = ["# The twin's protocol (chronological 80/20 per run; fits on the first 80 %, scores on the last 20 %)"]
    limit = report.get("limit")
    if limit:
        lines += ["", "## The limit: explained variance of the test readings by a smooth map of the probe pose", "",
                  "| run / stream | map (CV on the first 80 %) | test EV | with the run's time | map |",
                  "|---|---|---|---|---|"]
        for key, row in limit.items():
            if key == "zero_label_bound":
                continue
            best, timed = row["pose"], row["pose_and_time"]
            lines.append(f"| {key} | {best['best']} | {best['test_ev']:.3f} | {timed['test_ev']:.3f} | "
                         f"{timed['best']} |")
        if "zero_label_bound" in limit:
            b = limit["zero_label_bound"]
            lines += ["", f"Zero-label bound: the best smooth map (every label of the first 80 %) read backwards "
                          f"places the spatial run's {b['test_presses']} test presses {b['position_rmse_mm']:.2f} mm "
                          f"RMSE off."]
    forward = report.get("forward")
    if forward:
        lines += ["", "## Forward fidelity of the twin (baseline-subtracted test readings)", ""]
        if "note" in forward:
            lines.append(forward["note"])
        else:
            lines += ["| board / run | test EV |", "|---|---|"]
            lines += [f"| {key} | " + _forward_cell(row) + " |" for key, row in forward.items()]
    contact = report.get("contact")
    if contact:
        lines += ["", "## Contact from the twin against the number of labelled presses K (mean of seeds)"]
        for kind, block in contact.items():
            unit = "mm (2-D position)" if block["figure"] == "position_rmse_mm" else "N (normal force)"
            found = {m for row in block["k"].values() for m in row["mean"]}
            methods = [m for m in ORDER if m in found] + sorted(found - set(ORDER))
            lines += ["", f"{block['run']}: test RMSE, {unit}", "",
                      "| K | " + " | ".join(methods) + " |", "|---" * (len(methods) + 1) + "|"]
            for k, row in block["k"].items():
                seeds = row.get("seeds", {})  # where a mean covers fewer seeds than the others, which
                most = max((len(v) for v in seeds.values()), default=0)
                fewer = [f"{m}: seed {', '.join(map(str, v))}" for m, v in seeds.items() if len(v) < most]
                if most == 1 and k != "0":  # every mean of the row is one seed's
                    fewer = [f"seed {next(iter(seeds.values()))[0]}"]
                k = f"{k} ({'; '.join(fewer)})" if fewer else k
                lines.append(f"| {k} | " + " | ".join(f"{row['mean'][m]:.3f}" if m in row["mean"] else "-"
                                                      for m in methods) + " |")
    return "\n".join(lines)


def _forward_cell(row: dict[str, Any]) -> str:
    if "test_ev" in row:
        return f"{row['test_ev']:.3f}"
    if "note" in row:
        return row["note"]
    stages = row["fit_stages"]
    ev = stages["readout"]["ev"]
    cell = f"no rig frame without labels (its latent presses explain {ev:.3f} of the fitted readings)"
    if "position_rmse_mm" in row:
        cell += (f"; zero labels: position RMSE {row['position_rmse_mm']:.2f} mm on the {row['test_presses']} test "
                 "presses read backwards on the twin and refitted on a smooth model of the first 80 %'s readings "
                 "(read backwards alone: " + (f"{row['read_backwards_position_rmse_mm']:.2f} mm"
                                              if "read_backwards_position_rmse_mm" in row else "-")
                 + "), offset and quarter turn fitted on them")
    if "bound_every_label" in row:
        b = row["bound_every_label"]
        cell += (f" (the twin fitted with every label of the first 80 %, the same way: {b['position_rmse_mm']:.2f} mm"
                 + (f", read backwards alone {b['read_backwards_position_rmse_mm']:.2f} mm"
                    if "read_backwards_position_rmse_mm" in b else "") + ")")
    return cell


def plot(report: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    blocks = report.get("contact") or {}
    if not blocks:
        return
    fig, axes = plt.subplots(1, len(blocks), figsize=(5.5 * len(blocks), 4.2), squeeze=False)
    for ax, (kind, block) in zip(axes[0], blocks.items()):
        ks = list(block["k"])
        xs = [max(int(k), 1) for k in ks]
        for m in sorted({m for row in block["k"].values() for m in row["mean"]}):
            pts = [(x, block["k"][k]["mean"][m]) for x, k in zip(xs, ks) if m in block["k"][k]["mean"]]
            ax.plot(*zip(*pts), "o-", label=m)
        ax.set_xscale("log")
        ax.set_xticks(xs, ks)
        ax.set_xlabel("labelled presses K (0 plotted at 1)")
        ax.set_ylabel("test RMSE, " + ("mm" if block["figure"] == "position_rmse_mm" else "N"))
        ax.set_title(block["run"])
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=Path, default=DEFAULT_RUNS, help="folder holding spatial_* and normal_* runs")
    p.add_argument("--kind", nargs="+", choices=(SPATIAL, NORMAL), default=[SPATIAL, NORMAL], help="which runs")
    p.add_argument("--sections", nargs="+", choices=("limit", "forward", "zero_label", "contact"),
                   default=["limit", "forward", "contact"])
    p.add_argument("--k", type=int, nargs="+", default=[0, 10, 25, 100], help="labelled presses per case")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    p.add_argument("--presses", type=int, default=3000, help="the twin's simulated presses")
    p.add_argument("--twins", nargs="+", choices=("twin", "bound"), default=["twin"],
                   help="contact cases: the fitted twin (the shipped board where fit-board is missing), and the bound "
                        "(a smooth map of the pose fitted with every label of the first 80 %% as the twin)")
    p.add_argument("--board", default="eflesh", metavar="NAME|FILE",
                   help="the board file the runs are imported with and fitted from (default eflesh); a cache folder "
                        "(--work) holds one board's files")
    p.add_argument("--work", type=Path, default=None, help="cache folder (default: a temporary one)")
    p.add_argument("--out", type=Path, default=Path("docs/results/twin/twin_protocol.json"))
    p.add_argument("--update", action="store_true", help="keep the sections of --out this call does not run")
    args = p.parse_args(argv)
    TEMPLATE["board"] = args.board
    runs = {k: v for k, v in run_folders(args.runs).items() if k in args.kind}
    report: dict[str, Any] = json.loads(args.out.read_text()) if args.update and args.out.is_file() else {}
    report.update({"machine": machine_info(),  # --update keeps the runs this call does not measure
                   "runs": {**report.get("runs", {}), **{k: v.name for k, v in runs.items()}}})
    if args.board != "eflesh":
        report.setdefault("board_by_section", {}).update({s: args.board for s in args.sections})
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        for section in args.sections:
            start = time.perf_counter()
            print(f"== {section}", flush=True)
            if section == "limit":
                report["limit"] = section_limit(runs, work)
            elif section == "forward":
                report["forward"] = section_forward(runs, work)
            elif section == "zero_label":  # the forward table's no-label rows alone
                report.setdefault("forward", {}).update(section_zero_label(runs, work))
            else:
                new = section_contact(runs, work, args.k, args.seeds, presses=args.presses, twins=args.twins)
                for kind, block in new.items():  # --update keeps the other runs', K's and methods' figures
                    kept = report.setdefault("contact", {}).setdefault(kind, block)
                    kept["k"] = {**kept["k"], **{k: merged_row(kept["k"].get(k, {}), row)
                                                 for k, row in block["k"].items()}}
                    kept["k"] = dict(sorted(kept["k"].items(), key=lambda kv: int(kv[0])))
            report.setdefault("seconds", {})[section] = round(time.perf_counter() - start, 1)
            print(f"== {section}: {time.perf_counter() - start:.0f} s", flush=True)
    publish(report, args.out, markdown)
    args.out.with_suffix(".md").write_text(markdown(report).strip() + "\n")
    plot(report, args.out.with_suffix(".png"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
