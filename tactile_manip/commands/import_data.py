"""``tactile-manip import``: a paired dataset from plain arrays (.npy files, one .npz of named arrays, HDF5).

    tactile-manip import --readings R.npy --images I.npy --out D.npz
    tactile-manip import --arrays mine.npz --channel-kind scalar --reading-unit pF --image-unit fraction \\
        --data-range 1 --pixel-mm 0.25 --groups-from participant --out D.npz

With ``--arrays FILE`` (.npz, or .h5 with the ``hdf5`` extra) the arrays are read by name: readings, images,
split, groups, objects by default, or the names given to --readings/--images/--split/--groups/--objects.
"""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    src = p.add_argument_group("arrays")
    src.add_argument("--arrays", metavar="FILE", help="one .npz (or .h5) of named arrays")
    src.add_argument("--readings", metavar="NPY|NAME",
                     help="(N, R, C[, A]) readings: a .npy file, or an array name in --arrays (default 'readings')")
    src.add_argument("--images", metavar="NPY|NAME", help="(N, H, W) images: .npy file or array name")
    src.add_argument("--split", metavar="NPY|NAME", help="(N,) of train/val/test (default: drawn at random)")
    src.add_argument("--groups", metavar="NPY|NAME",
                     help="(N,) ids of samples that belong together (one contact, one participant); never cut by "
                          "a split")
    src.add_argument("--objects", metavar="NPY|NAME", help="(N,) names of what was pressed (per-object tables)")
    sp = p.add_argument_group("split when none is given")
    sp.add_argument("--val-fraction", type=float, default=0.1, help="share of samples (or groups) for validation")
    sp.add_argument("--test-fraction", type=float, default=0.1, help="share of samples (or groups) for test")
    sp.add_argument("--seed", type=int, default=0, help="seed of the random split")
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
    from tactile_manip.outputs import check_output_file

    out = check_output_file(dataset_path(args.out), force=args.force)  # the file written, before reading anything
    arrays = {name: _read(args, name) for name in ("readings", "images", "split", "groups", "objects")}
    for name in ("readings", "images"):
        if arrays[name] is None:
            raise ValueError(f"--{name} is required (a .npy file, or an array name with --arrays)")
    names = tuple(n.strip() for n in args.channel_names.split(",")) if args.channel_names else None
    data = from_arrays(
        arrays["readings"], arrays["images"], split=arrays["split"], groups=arrays["groups"],
        objects=arrays["objects"], val_fraction=args.val_fraction, test_fraction=args.test_fraction,
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
