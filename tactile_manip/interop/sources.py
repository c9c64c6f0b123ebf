"""Sources of episodes: a trial run folder, a sensor recording (``record``) or a collector's pair log.

:func:`read_source` looks at a path and turns what it holds into :class:`~tactile_manip.interop.frames.Episode`
lists on the sensor clock:

- a trial run folder (``trials.jsonl`` and ``frames/``, written by ``tactile-manip trials``): one episode per
  trial and method, the task from the trial's object and target, ``success`` at the run's tolerance;
- a recording (``.tmrec``): one episode of every frame; a recording holds raw fields (no baseline was taken),
  so ``field_ut`` is the raw field;
- a pair log: one episode per object, in log order, each pair a frame with the VBTS depth beside the field.

A damaged source gives what is intact: a torn or corrupt line of the trial log, a missing or unreadable frames
file, damaged records in the middle of a file and a torn tail are skipped, and :attr:`Source.skipped` says
what, one line each. Only a path that is none of the three, or that holds nothing intact, is an error.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tactile_manip.behaviours.registry import DEFAULT_TASK
from tactile_manip.errors import RecordingError
from tactile_manip.interop.frames import Episode, Frame

KINDS = ("trials", "recording", "pairs")


@dataclass
class Source:
    """What a source path gave.

    Attributes:
        path: the source.
        kind: one of KINDS.
        episodes: the intact episodes, indexed 0, 1, ... in source order.
        skipped: what was left out or lost, one human-readable line each (empty for an undamaged source).
        meta: facts of the whole source (run config, recording header, pair log header).
    """

    path: Path
    kind: str
    episodes: list[Episode]
    skipped: list[str] = field(default_factory=list)
    meta: dict = field(default_factory=dict)

    @property
    def frames(self) -> int:
        return sum(len(e.frames) for e in self.episodes)


class SourceError(RecordingError):
    """A source path is not a trial run, a recording or a pair log, or nothing in it is intact."""


def read_source(path: str | Path) -> Source:
    """The episodes of a trial run folder, a recording or a pair log (see the module docstring).

    Raises:
        SourceError: the path is missing or none of the three, or no episode in it is intact.
    """
    from tactile_manip.collection.pair_log import MAGIC as PAIRS_MAGIC
    from tactile_manip.logs.recording import MAGIC as RECORDING_MAGIC

    path = Path(path)
    if path.is_dir():
        if not (path / "trials.jsonl").is_file():
            raise SourceError(f"{path} is a folder without trials.jsonl: give a trial run folder (made by "
                              "`tactile-manip trials`), a recording (.tmrec) or a pair log")
        source = _read_trials(path)
    elif not path.exists():
        raise SourceError(f"no such source: {path}")
    else:
        with open(path, "rb") as f:
            head = f.read(64)
        if head.startswith(RECORDING_MAGIC):
            source = _read_recording(path)
        elif head.startswith(PAIRS_MAGIC):
            source = _read_pairs(path)
        else:
            raise SourceError(f"{path} is not a trial run folder, a recording or a pair log of tactile_manip")
    if not source.episodes:
        detail = "; ".join(source.skipped) or "it holds no frame"
        raise SourceError(f"nothing to export from {path}: {detail}")
    return source


# ---------------------------------------------------------------------------------------------- trial runs

def _read_trials(run: Path) -> Source:
    from tactile_manip.trials.frames import PHASES, frames_path, read_trial_frames
    from tactile_manip.trials.log import read_run_info

    from tactile_manip.trials.log import TrialLogError

    skipped_info = []
    try:
        info = read_run_info(run) or {}
    except TrialLogError as e:  # the run's description is damaged: the trials still carry what they need
        info = {}
        skipped_info.append(f"run.json: {e}; the success tolerance defaults to 5 deg")
    config = info.get("config") or {}
    tolerance = math.radians(float(config.get("tolerance_deg", 5.0)))
    records, skipped = _tolerant_records(run / "trials.jsonl")
    skipped = skipped_info + skipped
    episodes: list[Episode] = []
    for r in records:
        label = f"trial {r.trial} ({r.method})"
        file = frames_path(run, r.trial, r.method)
        if not file.is_file():
            skipped.append(f"{label}: no frames file {file.relative_to(run)} (run with --no-frames, or stopped "
                           "before the trial)")
            continue
        try:
            frames = read_trial_frames(file)
        except RecordingError as e:
            skipped.append(f"{label}: {e}")
            continue
        lost = _lost(frames.truncated_bytes, frames.skipped_bytes, frames.damaged_records)
        if lost:
            skipped.append(f"{label}: {lost}; kept its {len(frames)} intact frames")
        if len(frames) == 0:
            skipped.append(f"{label}: no frame recorded")
            continue
        episodes.append(_trial_episode(len(episodes), r, frames, tolerance, PHASES, run))
    return Source(run, "trials", episodes, skipped, meta={"run": info})


def _tolerant_records(file: Path):
    """Every trial record of the log that parses; the lines that do not are reported, never raised."""
    from tactile_manip.trials.record import RECORD_VERSION, TrialRecord

    records, skipped = [], []
    lines = file.read_bytes().split(b"\n")
    last = max((i for i, line in enumerate(lines, start=1) if line.strip()), default=0)
    for lineno, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            d = json.loads(line)
            if not isinstance(d, dict) or d.get("version", RECORD_VERSION) > RECORD_VERSION:
                raise ValueError("not a trial record of a version this code reads")
            records.append(TrialRecord.from_dict(d))
        except (ValueError, TypeError, UnicodeDecodeError) as e:
            what = "a torn last line" if lineno == last else "a damaged line"
            skipped.append(f"trials.jsonl:{lineno}: {what} was skipped ({str(e)[:80]})")
    return records, skipped


def _trial_episode(index: int, r, frames, tolerance_rad: float, phases: tuple[str, ...], run: Path) -> Episode:
    rows, header = frames.rows, frames.header
    fps = float(header["rate_hz"])
    joints_known = bool(np.isfinite(rows["joints_rad"]).any())
    out = []
    for k in range(len(rows)):
        row = rows[k]
        out.append(Frame(t_s=k / fps, host_time_s=float(frames.t_host_s[k]), field_ut=np.array(row["field_ut"]),
                         angle_rad=float(row["angle_rad"]), confidence=float(row["confidence"]),
                         joints_rad=np.array(row["joints_rad"]) if joints_known else None,
                         gripper_width_m=float(row["gripper_width_m"]), target_angle_rad=float(row["target_angle_rad"]),
                         phase=phases[int(row["phase"])], field_raw_ut=np.array(row["field_raw_ut"])))
    target_deg = math.degrees(r.target_angle_rad)
    meta = {"source": "trials", "run": str(run), "trial": r.trial, "method": r.method, "seed": r.seed,
            "object": r.object, "outcome": r.outcome, "error_rad": r.error_rad, "true_angle_rad": r.true_angle_rad,
            "estimated_angle_rad": r.estimated_angle_rad, "confidence": r.confidence, "regrasps": r.regrasps,
            "tolerance_rad": tolerance_rad, "layout": header.get("layout"), "grid": header.get("grid"),
            "frames_file": str(frames.path.relative_to(run)),
            "frames_lost_on_disk": int(frames.damaged_records), "seq_gaps": _gaps(rows["seq"])}
    if r.estimated_grip_force_n is not None:  # the scene had a contact model
        meta.update(estimated_grip_force_n=r.estimated_grip_force_n,
                    estimated_grip_force_sigma_n=r.estimated_grip_force_sigma_n)
    return Episode(index=index, task=f"{r.task or DEFAULT_TASK} {r.object} to {target_deg:g} deg", fps=fps, frames=out,
                   success=r.succeeded(tolerance_rad), meta=meta)


# ---------------------------------------------------------------------------------------------- recordings

def _read_recording(path: Path) -> Source:
    from tactile_manip.logs.recording import read_recording

    rec = read_recording(path)
    skipped = []
    lost = _lost(rec.truncated_bytes, rec.skipped_bytes, rec.damaged_records)
    if lost:
        skipped.append(f"{path.name}: {lost}; kept its {len(rec)} intact frames")
    gaps = _gaps(rec.seq)
    if gaps:
        skipped.append(f"{path.name}: {gaps} frames never reached the recorder (sequence gaps); the episode's "
                       "grid closes over them, host_time_s keeps the true times")
    if len(rec) == 0:
        return Source(path, "recording", [], [*skipped, f"{path.name}: no frame"], meta={"header": rec.header})
    fps = float(rec.header.get("chip", {}).get("rate_hz") or 125.0)
    raw = rec.field_raw_ut()
    frames = [Frame(t_s=k / fps, host_time_s=float(rec.t_host_s[k]), field_ut=raw[k]) for k in range(len(rec))]
    meta = {"source": "recording", "file": str(path), "layout": rec.layout_name, "sensor": rec.header.get("source"),
            "chip": rec.header.get("chip"), "baseline": "none: the field is raw (a recording takes no baseline)",
            "seq_first": int(rec.seq[0]), "seq_gaps": gaps}
    episode = Episode(index=0, task=f"tactile recording {path.stem}", fps=fps, frames=frames, meta=meta)
    return Source(path, "recording", [episode], skipped, meta={"header": rec.header})


# ---------------------------------------------------------------------------------------------- pair logs

def _read_pairs(path: Path) -> Source:
    from tactile_manip.collection.pair_log import read_pair_log
    from tactile_manip.data import DEPTH_SCALE_MM

    log = read_pair_log(path)
    skipped = []
    lost = _lost(log.truncated_bytes, log.skipped_bytes, log.damaged_records)
    if lost:
        skipped.append(f"{path.name}: {lost}; kept its {len(log)} intact pairs")
    fps = float(log.header.get("rate_hz") or log.header.get("chip", {}).get("rate_hz") or 125.0)
    by_object: dict[str, list] = {}
    for p in log.pairs:
        by_object.setdefault(str(p.info.get("object", "object")), []).append(p)
    episodes = []
    for obj, pairs in by_object.items():
        frames = [Frame(t_s=k / fps, host_time_s=float(p.info.get("t_field_s", math.nan)), field_ut=p.field_ut,
                        vbts_depth_mm=p.depth_q.astype(np.float32) * np.float32(DEPTH_SCALE_MM),
                        field_raw_ut=p.field_raw_ut) for k, p in enumerate(pairs)]
        meta = {"source": "pairs", "file": str(path), "object": obj, "pixel_mm": log.header.get("pixel_mm"),
                "presses": sorted({p.info.get("press") for p in pairs if p.info.get("press") is not None}),
                "force_n": [p.info.get("force_n") for p in pairs],
                "depth_scale_mm": DEPTH_SCALE_MM,
                "note": "frames are consecutive pairs (one per triggered camera frame), not consecutive sensor "
                        "frames: host_time_s holds when each was taken"}
        episodes.append(Episode(index=len(episodes), task=f"press {obj} on the sensor pair", fps=fps, frames=frames,
                                meta=meta))
    header = {k: v for k, v in log.header.items() if k != "calibration"}
    return Source(path, "pairs", episodes, skipped,
                  meta={"header": header, "calibration": log.header.get("calibration")})


# ---------------------------------------------------------------------------------------------- helpers

def _lost(truncated_bytes: int, skipped_bytes: int, damaged_records: int) -> str:
    parts = []
    if damaged_records:
        parts.append(f"{damaged_records} damaged place(s) ({skipped_bytes} bytes) skipped")
    if truncated_bytes:
        parts.append(f"a torn tail of {truncated_bytes} bytes dropped")
    return ", ".join(parts)


def _gaps(seq: np.ndarray) -> int:
    """Frames missing inside a sequence of frame counters (0 when contiguous)."""
    if len(seq) < 2:
        return 0
    step = np.diff(np.asarray(seq, np.int64))
    return int(np.clip(step - 1, 0, None).sum())
