"""``tactile-manip import``: a dataset from plain arrays (.npy files, one .npz of named arrays, HDF5), or
labelled presses from a probe rig's logs.

    tactile-manip import --readings R.npy --images I.npy --out D.npz
    tactile-manip import --arrays mine.npz --channel-kind scalar --reading-unit pF --image-unit fraction \\
        --data-range 1 --pixel-mm 0.25 --groups-from participant --out D.npz
    tactile-manip import --readings-csv SENSOR.csv --labels-csv STATES.csv \\
        --label-columns time_s,x_mm,y_mm,z_mm --contact "z_mm < 145.1" --targets x_mm,y_mm --layout anyskin-5 \\
        --out D.npz

With ``--arrays FILE`` (.npz, or .h5 with the ``hdf5`` extra) the arrays are read by name: readings, images,
split, groups, objects by default, or the names given to --readings/--images/--split/--groups/--objects.
With ``--readings-csv``/``--labels-csv`` (one pair per run) the streams are matched by time
(:func:`tactile_manip.data.from_probe_logs`) and a summary per run is printed.
"""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    src = p.add_argument_group("arrays")
    src.add_argument("--arrays", metavar="FILE", help="one .npz (or .h5) of named arrays")
    src.add_argument("--readings", metavar="NPY|NAME",
                     help="(N, R, C[, A]) readings: a .npy file, or an array name in --arrays (default 'readings')")
    src.add_argument("--images", metavar="NPY|NAME", help="(N, H, W) images: .npy file or array name")
    src.add_argument("--split", metavar="NPY|NAME|KIND",
                     help="(N,) of train/val/test (default: drawn at random); with probe logs: chronological "
                          "(default: per run, first rows train, last --test-fraction test) or held-out-run")
    src.add_argument("--groups", metavar="NPY|NAME",
                     help="(N,) ids of samples that belong together (one contact, one participant); never cut by "
                          "a split")
    src.add_argument("--objects", metavar="NPY|NAME", help="(N,) names of what was pressed (per-object tables)")
    probe = p.add_argument_group("probe logs (labelled presses)")
    probe.add_argument("--readings-csv", action="append", metavar="FILE", default=[],
                       help="sensor stream of one run: CSV of time (s), then x, y, z of each chip in uT (chip-major), "
                            "or a `tactile-manip record` file (.tmrec); repeat once per run")
    probe.add_argument("--labels-csv", action="append", metavar="FILE", default=[],
                       help="label stream of the same run: CSV of time (s) and label columns; repeat once per run")
    probe.add_argument("--label-columns", metavar="A,B,...",
                       help="names of the label CSV's columns, with units: time_s,x_mm,y_mm,z_mm,force_gf "
                            "(default: the CSV's header)")
    probe.add_argument("--targets", metavar="A,B,...",
                       help="label columns to learn, in target units: x_mm,y_mm / force_n (from force_gf, in N) / "
                            "in_contact (the --contact flag)")
    probe.add_argument("--contact", metavar="EXPR",
                       help='keep the rows where one comparison on a label column holds, e.g. "z_mm < 145.1" '
                            "(with the in_contact target: label every row by it instead)")
    probe.add_argument("--missing", action="append", metavar="VALUE|COLUMN=VALUE", default=[],
                       help="value meaning 'no reading' in the used label columns (e.g. -1), or in one column "
                            "(force_gf=-1); such label rows are not matched")
    probe.add_argument("--board", "--layout", dest="layout", default="anyskin-5", metavar="NAME|FILE",
                       help="the board of the readings: a shipped board (anyskin-5: 5 chips in a cross on 3x3 cells; "
                            "eflesh; supermag-4x4), generic:N (N chips, no geometry) or a board file (.toml); "
                            "--layout is the same option")
    probe.add_argument("--labelled", type=int, default=None, metavar="K",
                       help="keep the labels of K training presses drawn at random (with --seed); the other training "
                            "rows stay as unlabelled readings (split 'unlabelled'); validation and test keep theirs")
    probe.add_argument("--tolerance-s", type=float, default=None,
                       help="largest sensor-to-label time difference matched, s (default 3 median label periods)")
    probe.add_argument("--match", choices=("nearest", "linear"), default="nearest",
                       help="label of a sensor row: the nearest usable label row (default, the published protocol) "
                            "or targets interpolated in time between the usable rows on either side")
    probe.add_argument("--held-out-run", metavar="INDEX|NAME", help="the test run of --split held-out-run")
    probe.add_argument("--run-names", metavar="A,B,...", help="one name per run (default: each readings file's folder)")
    probe.add_argument("--time-offset-s", type=float, default=0.0,
                       help="added to every sensor time, s (to put both streams on one clock)")
    probe.add_argument("--baseline-s", type=float, default=None,
                       help="subtract the mean of each run's first S seconds of readings (default: readings as "
                            "given; a .tmrec holds raw fields)")
    sp = p.add_argument_group("split when none is given")
    sp.add_argument("--val-fraction", type=float, default=None,
                    help="share of samples (or groups) for validation (default 0.1; probe logs 0: taken from the end "
                         "of each run's training rows)")
    sp.add_argument("--test-fraction", type=float, default=None,
                    help="share of samples (or groups) for test (default 0.1; probe logs 0.2: the last rows of each "
                         "run)")
    sp.add_argument("--seed", type=int, default=0, help="seed of the random split, and of --labelled's draw")
    units = p.add_argument_group("what the numbers mean")
    units.add_argument("--channel-kind", choices=("magnetic_vector", "scalar"),
                       help="magnetic_vector (3 channels x, y, z in the pad frame: turned by the pad's symmetries) "
                            "or scalar (default: magnetic_vector for 3 channels, else scalar)")
    units.add_argument("--channel-names", metavar="A,B,C", help="channel names (default x,y,z or c0,c1,...)")
    units.add_argument("--reading-unit", help="unit of the readings (default uT for 3 channels, else 1)")
    units.add_argument("--image-unit", default="mm", help="unit of the images: mm (depth), fraction, grey, ...")
    units.add_argument("--pixel-mm", type=float, default=None, help="image pixel pitch on the pad, mm")
    units.add_argument("--data-range", type=float, default=None,
                       help="width of the images' value interval (PSNR/SSIM L; default: the span of the data)")
    units.add_argument("--value-min", type=float, default=None, help="lowest valid image value (default 0)")
    p.add_argument("--out", required=True, help="output dataset .npz")
    p.add_argument("--force", action="store_true", help="overwrite an existing output file")


def run(args: argparse.Namespace) -> int:
    from tactile_manip.data import dataset_path, from_arrays, save_dataset
    from tactile_manip.data.io import written_by
    from tactile_manip.outputs import check_output_file

    out = check_output_file(dataset_path(args.out), force=args.force, ours=written_by("tactile-manip import"),
                            what="dataset written by tactile-manip import")  # before reading anything
    if args.readings_csv or args.labels_csv:
        return _run_probe_logs(args, out)
    probe_only = [f"--{k.replace('_', '-')}" for k in ("label_columns", "targets", "contact", "held_out_run", "labelled")
                  if getattr(args, k) is not None]
    if probe_only:
        raise ValueError(f"{', '.join(probe_only)} go with probe logs (--readings-csv and --labels-csv)")
    arrays = {name: _read(args, name) for name in ("readings", "images", "split", "groups", "objects")}
    for name in ("readings", "images"):
        if arrays[name] is None:
            raise ValueError(f"--{name} is required (a .npy file, or an array name with --arrays)")
    names = tuple(_names(args.channel_names, "--channel-names")) if args.channel_names else None
    data = from_arrays(
        arrays["readings"], arrays["images"], split=arrays["split"], groups=arrays["groups"],
        objects=arrays["objects"], val_fraction=_or(args.val_fraction, 0.1),
        test_fraction=_or(args.test_fraction, 0.1),
        seed=args.seed, channel_names=names, channel_kind=args.channel_kind, reading_unit=args.reading_unit,
        image_unit=args.image_unit, pixel_mm=args.pixel_mm, data_range=args.data_range, value_min=args.value_min,
        provenance={"source": "tactile-manip import", "inputs": _inputs(args)})
    path = save_dataset(out, data)
    d = data.describe()
    ch, im = d["channels"], d["image"]
    print(f"wrote {path}: {d['samples']} pairs ({d['splits']['train']} train / {d['splits']['val']} val / "
          f"{d['splits']['test']} test), fingerprint {d['fingerprint']}")
    print(f"  readings {d['grid'][0]}x{d['grid'][1]} taxels x {len(ch['names'])} channels {','.join(ch['names'])}: "
          f"{ch['kind']} in {ch['unit']}")
    pixel = "unknown" if im["pixel_mm"] is None else f"{im['pixel_mm']:g} mm"
    print(f"  images {d['image_shape'][0]}x{d['image_shape'][1]} px in {im['unit']}, range "
          f"[{im['value_min']:g}, {im['value_min'] + im['data_range']:g}], pixel {pixel}")
    return 0


def _run_probe_logs(args: argparse.Namespace, out) -> int:
    from tactile_manip.data import from_probe_logs, save_dataset

    if len(args.readings_csv) != len(args.labels_csv):
        raise ValueError(f"one --labels-csv per --readings-csv (one pair per run): got {len(args.readings_csv)} "
                         f"--readings-csv and {len(args.labels_csv)} --labels-csv")
    given = [f"--{k}" for k in ("arrays", "readings", "images", "groups", "objects") if getattr(args, k) is not None]
    if given:
        raise ValueError(f"{', '.join(given)} make a dataset from arrays; probe logs take --readings-csv and "
                         f"--labels-csv only")
    if not args.targets:
        raise ValueError("--targets is required with probe logs (e.g. --targets x_mm,y_mm or --targets force_n)")
    split = (args.split or "chronological").replace("-", "_")
    data = from_probe_logs(
        args.readings_csv, args.labels_csv, targets=_names(args.targets, "--targets"),
        label_columns=_names(args.label_columns, "--label-columns"),
        layout=args.layout, contact=args.contact, missing=_missing(args.missing), tolerance_s=args.tolerance_s,
        match=args.match, split=split, test_fraction=_or(args.test_fraction, 0.2),
        val_fraction=_or(args.val_fraction, 0.0), held_out_run=args.held_out_run,
        run_names=_names(args.run_names, "--run-names"), time_offset_s=args.time_offset_s, baseline_s=args.baseline_s,
        labelled=args.labelled, seed=args.seed,
        provenance={"source": "tactile-manip import", "inputs": {"readings_csv": args.readings_csv,
                                                                 "labels_csv": args.labels_csv}})
    for line in probe_summary(data):
        print(line)
    path = save_dataset(out, data)
    d = data.describe()
    units = ", ".join(f"{n} [{u}]" for n, u in d["targets"].items())
    splits = {name: d["splits"].get(name, 0) for name in ("train", "val", "test", "unlabelled")}
    held = (f", {splits['unlabelled']} more training presses without their labels (--labelled "
            f"{data.provenance['labelled']['presses']}, seed {data.provenance['labelled']['seed']})"
            if "labelled" in data.provenance else "")
    print(f"wrote {path}: {d['samples']} {'presses' if held else 'labelled presses'} in "
          f"{len(data.provenance['runs'])} run(s) "
          f"({splits['train']} train / {splits['val']} val / {splits['test']} test{held}), "
          f"targets {units}, "
          f"layout {data.provenance['layout']} ({d['grid'][0]}x{d['grid'][1]} cells), fingerprint {d['fingerprint']}")
    return 0


def probe_summary(data) -> list[str]:
    """Three lines per run of a probe-log import: rows, what was matched and dropped, gaps and split sizes; one
    more for repeated times, and one for what a damaged recording lost."""
    lines = []
    for r in data.provenance["runs"]:
        matched = r["reading_rows"] - r["nan_readings"] - r["unmatched"]
        how = f"median |dt| {1e3 * r['median_match_dt_s']:.3g} ms, 90 % within {1e3 * r['p90_match_dt_s']:.3g} ms"
        how += f", {r['interpolated']} interpolated" if r["interpolated"] else ""
        contact = "" if "non_contact" not in r else f", not in contact {r['non_contact']} (dropped)"
        rg, lg = r["reading_gaps"], r["label_gaps"]
        lines += [f"run {r['name']}: {r['reading_rows']} sensor rows, {r['label_rows']} label rows "
                  f"({r['missing_labels']} without a reading, not matched)",
                  f"  matched {matched} ({how}), unmatched {r['unmatched']}, NaN readings skipped "
                  f"{r['nan_readings']}{contact}",
                  f"  time gaps > {r['tolerance_s']:.3g} s: {rg['count']} in the sensor stream (longest "
                  f"{rg['longest_s']:.3g} s), {lg['count']} in the labels (longest {lg['longest_s']:.3g} s); "
                  f"{r['samples']} samples: {r['train']} train / {r['val']} val / {r['test']} test"]
        lines += [line for line in (_repeated_times(r), _recording_losses(r["readings"])) if line]
    return lines


def _repeated_times(run: dict) -> str | None:
    """One line on the rows whose time repeats the row before, or None when no time repeats."""
    parts = []
    for stream, name in (("reading", "sensor"), ("label", "label")):
        count, first = run.get(f"repeated_{stream}_times", 0), run.get(f"first_repeated_{stream}_row")
        rows = "row" if count == 1 else "rows"
        parts.append(f"{count} {name} {rows}" + (f" (first at row {first})" if count else ""))
    if not run.get("repeated_reading_times") and not run.get("repeated_label_times"):
        return None
    return f"  repeated times: {', '.join(parts)}; each sensor row is kept, a repeated label time matches its first row"


def _recording_losses(info: dict) -> str | None:
    """One line on what a damaged recording lost (bytes, places, about how many frames, where), or None."""
    skipped, tail = info.get("skipped_bytes", 0), info.get("truncated_bytes", 0)
    if not skipped and not tail:
        return None
    places = info.get("damaged_places", 0)
    at = [str(a) for a in info.get("damage_at_bytes", []) if a >= 0]
    where = f", at byte{'s' if len(at) > 1 else ''} {', '.join(at[:5])}{', ...' if len(at) > 5 else ''}" if at else ""
    parts = [f"{skipped} damaged bytes skipped in {places} place{'s' if places != 1 else ''}"] if skipped else []
    parts += [f"a torn tail of {tail} bytes"] if tail else []
    frames = info.get("frames_lost", 0)
    return (f"  recording {info['source']}: {' and '.join(parts)} (about {frames} frame{'s' if frames != 1 else ''}"
            f"{where})")


def _names(text: str | None, flag: str) -> list[str] | None:
    """The comma-separated names of ``flag``; ValueError naming a name given twice."""
    if text is None:
        return None
    names = [n.strip() for n in text.split(",") if n.strip()]
    twice = [n for i, n in enumerate(names) if n in names[:i]]
    if twice:
        raise ValueError(f"{flag} names {twice[0]!r} twice ({','.join(names)}): give each once")
    return names


def _missing(values: list[str]) -> float | dict[str, float] | None:
    """``--missing -1`` (every used column) or ``--missing force_gf=-1`` (repeatable, per column)."""
    if not values:
        return None
    plain = [v for v in values if "=" not in v]
    if plain and len(values) > 1:
        raise ValueError(f"--missing: give one value for every column, or COLUMN=VALUE per column, not both: {values}")
    try:
        if plain:
            return float(plain[0])
        return {k.strip(): float(v) for k, v in (item.split("=", 1) for item in values)}
    except ValueError:
        raise ValueError(f"--missing: expected a number or COLUMN=NUMBER, got {values}") from None


def _or(value, default):
    return default if value is None else value


def _read(args: argparse.Namespace, name: str):
    from tactile_manip.data import read_array
    from tactile_manip.data.imports import array_names

    given = getattr(args, name)
    if args.arrays:
        key = given or name
        if given is None and key not in array_names(args.arrays):
            return None
        return read_array(args.arrays, key)
    return None if given is None else read_array(given)


def _inputs(args: argparse.Namespace) -> dict[str, str]:
    keys = ("arrays", "readings", "images", "split", "groups", "objects")
    return {k: str(getattr(args, k)) for k in keys if getattr(args, k) is not None}
