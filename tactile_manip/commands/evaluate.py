"""``tactile-manip evaluate``: SuperMag's Table I on our unseen test objects, with a gallery figure.

On a dataset of labelled presses (targets, no images), or with contact models (``kind = "contact"`` in their
metadata) on any dataset with targets, images or not, it evaluates contact models instead: RMSE and MAE per
target, sigma calibration, per run and force band, against linear, kNN and MLP baselines fitted on the same
split (:mod:`tactile_manip.evaluation.contact`); it writes table.md, results.json and contact.png.

The interpolation baselines are fitted on the dataset's training split (``--baseline-objects`` narrows it to
some objects: our Table I fits them on the paper's two training objects, as the shipped fit is); models are
exported ``.onnx`` files given as ``--model LABEL=PATH`` (in table order).
"""

from __future__ import annotations

import argparse

import numpy as np

from tactile_manip.outputs import check_command_folder, claim_folder
from tactile_manip.extras import require

REPORT_FILES = ("table.md", "results.json", "gallery.png")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--data", required=True,
                   help="dataset .npz whose test split is evaluated: readings paired with depth images (image models), "
                        "or labelled presses (contact models; tactile-manip import)")
    p.add_argument("--model", action="append", default=[], metavar="LABEL=PATH",
                   help="an exported model, e.g. 'SuperMag=models/supermag.onnx' (repeatable)")
    p.add_argument("--symmetrized", action="append", default=[], metavar="LABEL=PATH",
                   help="an exported model averaged over the sensor's 8 symmetries (SymmetrizedReconstructor)")
    p.add_argument("--out", required=True, help="folder for table.md, results.json and gallery.png")
    p.add_argument("--force", action="store_true", help="replace the report files of an earlier evaluation in --out")
    p.add_argument("--split", default="test", choices=("train", "val", "test"),
                   help="the split of --data to score (default test; the others were trained or tuned on)")
    p.add_argument("--inception-onnx", default=None,
                   help="Inception-v3 pool features as ONNX ((N,3,299,299) -> (N,2048)) to report a real FID")
    p.add_argument("--threads", type=int, default=1, help="onnxruntime threads per model (default 1)")
    p.add_argument("--no-baselines", action="store_true",
                   help="skip the baselines (bilinear and bicubic; on labelled presses: linear, kNN, MLP)")
    p.add_argument("--baseline-channel", default=None, metavar="NAME",
                   help="channel the baselines upsample (default: z of a magnetic reading, else the first)")
    p.add_argument("--baseline-objects", default="", metavar="NAME,NAME",
                   help="fit the interpolation baselines' depth scale on the training presses of these objects "
                        "only (default: every object with training presses)")


def run(args: argparse.Namespace) -> int:
    from tactile_manip.evaluation.images import evaluate_methods, gallery, markdown_table, write_report
    from tactile_manip.perception.reconstruct import BASELINES, OnnxReconstructor
    from tactile_manip.data import load_dataset
    from tactile_manip.errors import DatasetError

    from tactile_manip.outputs import check_output_dir

    if args.model or args.symmetrized or args.inception_onnx:
        require("onnxruntime", "evaluating exported models")
    check_output_dir(args.out)  # before reading the data; which report files it will hold depends on them
    data = load_dataset(args.data)
    if _contact_models(args.model, data, args.data) or (not data.has_images and data.has_targets):
        return _run_contact(args, data)
    check_command_folder(args.out, "evaluate", REPORT_FILES, force=args.force)
    data.require_images(f"evaluate's image metrics (PSNR, SSIM, angle) on {args.data}")
    if not len(data.indices(args.split)):
        raise DatasetError(f"{args.data} has no {args.split} split to evaluate (its splits: "
                           f"{', '.join(sorted(set(data.split.tolist()))) or 'none'}); choose one with --split, or "
                           "give test objects when making it (`collect --test-objects`, a dataset config's "
                           "split = \"test\")")
    methods = {}
    if not args.no_baselines:
        train = _baseline_fit_indices(data, args.baseline_objects)
        geometry = BASELINES["bilinear"].geometry(data.readings.shape, data.image_shape, data.image.pixel_mm,
                                                  data.channels.index(args.baseline_channel))
        methods = {name.capitalize(): cls.fit(data.readings[train], data.image_values(train), **geometry)
                   for name, cls in BASELINES.items()}
    from tactile_manip.perception.symmetry import SymmetrizedReconstructor

    for option, specs in (("--model", args.model), ("--symmetrized", args.symmetrized)):
        for spec in specs:
            label, sep, path = spec.partition("=")
            if not sep or not label or not path:
                raise ValueError(f"{option} must be LABEL=PATH, got {spec!r}")
            model = OnnxReconstructor(path, threads=args.threads, image_symmetry="stored")  # the file's images
            _check_board(f"model {label} ({path})", model.metadata, data, args.data)
            methods[label] = SymmetrizedReconstructor(model) if option == "--symmetrized" else model
    results, _ = evaluate_methods(data, methods, split=args.split, inception_onnx=args.inception_onnx)
    rows = _gallery_rows(data, args.split, "val")
    write_report(claim_folder(args.out, "evaluate"), results,
                 {"data": str(args.data), "split": args.split, "data_fingerprint": data.fingerprint(),
                  "baseline_fits": {k: methods[k].to_dict() for k in ("Bilinear", "Bicubic") if k in methods},
                  "psnr_data_range": data.image.data_range, "image_unit": data.image.unit, "gallery_rows": rows})
    skipped = gallery(f"{args.out}/gallery.png", data, methods, rows)
    print(markdown_table(results), end="")
    if skipped:
        print(f"note: {', '.join(skipped)}: untrained (0 epochs in the model's metadata), left out of the gallery")
    print(f"wrote {args.out}/table.md, results.json, gallery.png")
    return 0


def _contact_models(specs: list[str], data, data_path: str) -> bool:
    """Whether the ``--model`` files are contact models (evaluated on the dataset's targets, whether or not it
    also holds images); ValueError for a mix of contact and image models or contact models on data without
    targets."""
    from tactile_manip.errors import DatasetError
    from tactile_manip.perception.reconstruct import read_metadata

    kinds = {}
    for spec in specs:
        label, sep, path = spec.partition("=")
        if sep and label and path:  # a malformed spec is refused where the models are loaded
            kinds[spec] = read_metadata(path).get("kind", "image")
    contact = [s for s, k in kinds.items() if k == "contact"]
    if not contact:
        return False
    if len(contact) != len(kinds):
        image = [s for s in kinds if s not in contact]
        raise ValueError(f"--model {contact[0]} is a contact model and --model {image[0]} an image model: evaluate "
                         "them in two runs (contact models on labelled presses, image models on images)")
    if not data.has_targets:
        label, _, path = contact[0].partition("=")
        raise DatasetError(f"--model {label}: {path} is a contact model, and {data_path} has no per-sample targets "
                           "to evaluate it on (it holds images only); evaluate it on labelled presses")
    return True


def _baseline_fit_indices(data, objects: str) -> np.ndarray:
    """Training presses of the named objects (comma-separated; all training presses when empty)."""
    train = data.indices("train")
    names = [n.strip() for n in objects.split(",") if n.strip()]
    if not names:
        return train
    trained = set(data.objects(train).tolist())
    unknown = [n for n in names if n not in trained]
    if unknown:
        raise ValueError(f"--baseline-objects: no training presses of {', '.join(unknown)} in this dataset; "
                         f"objects with training presses: {', '.join(sorted(trained))}")
    return data.indices("train", names)


def _gallery_rows(data, split: str, seen_split: str) -> list[tuple[str, int]]:
    """Two seen samples (one per training object) and one sample of each unseen object family."""
    rows = []
    for s in (seen_split, split):
        idx = data.indices(s)
        names = data.objects(idx)
        for n in list(dict.fromkeys(names.tolist()))[: 2 if s == seen_split else 7]:
            pos = int(np.flatnonzero(names == n)[0])
            rows.append((s, int(idx[pos])))
    return rows



CONTACT_REPORT_FILES = ("table.md", "results.json", "contact.png")


def _run_contact(args: argparse.Namespace, data) -> int:
    """Contact models and baselines on a dataset of labelled presses (see the module docstring)."""
    from tactile_manip.errors import DatasetError
    from tactile_manip.perception.contact import ContactEstimator
    from tactile_manip.evaluation.contact import evaluate_contact, markdown_table, write_contact_report

    unused = [f for f, v in (("--symmetrized", args.symmetrized), ("--inception-onnx", args.inception_onnx),
                             ("--baseline-channel", args.baseline_channel),
                             ("--baseline-objects", args.baseline_objects)) if v]
    if unused:
        raise ValueError(f"{', '.join(unused)}: for image datasets; {args.data} holds labelled presses")
    check_command_folder(args.out, "evaluate", CONTACT_REPORT_FILES, force=args.force)
    if not len(data.indices(args.split)):
        raise DatasetError(f"{args.data} has no {args.split} split to evaluate (its splits: "
                           f"{', '.join(sorted(set(data.split.tolist())))}); choose one with --split")
    models = {}
    for spec in args.model:
        label, sep, path = spec.partition("=")
        if not sep or not label or not path:
            raise ValueError(f"--model must be LABEL=PATH, got {spec!r}")
        models[label] = ContactEstimator(path, threads=args.threads)
        _check_board(f"model {label} ({path})", models[label].metadata, data, args.data)
    report = evaluate_contact(data, models, split=args.split, baselines=not args.no_baselines)
    write_contact_report(claim_folder(args.out, "evaluate"), report,
                         {"data": str(args.data), "data_fingerprint": data.fingerprint(),
                          "models": {k: str(m.path) for k, m in models.items()}})
    print(markdown_table(report), end="")
    print(f"wrote {args.out}/table.md, results.json, contact.png")
    return 0


def _check_board(what: str, metadata: dict, data, data_path: str) -> None:
    """Refuse a model of another board than the dataset's (one line naming both and what differs)."""
    from tactile_manip.boards.identity import check_same_board, record_of_metadata, record_of_provenance

    check_same_board(what, record_of_metadata(metadata), f"the dataset {data_path}",
                     record_of_provenance(data.provenance))
