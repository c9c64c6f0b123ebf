"""Per-sample targets of a labelled dataset: their names, units, and how labels in other units become them.

A target's name carries its unit as a suffix, like every quantity in this package:

======================  =====  =====================================================================
name                    unit   meaning
======================  =====  =====================================================================
``x_mm``, ``y_mm``      mm     contact position (the centroid of the contact patch, or the probe's
                               position in the rig's frame for probe logs)
``depth_mm``            mm     indentation depth of the skin
``force_n``             N      normal force
``shear_x_n``, ...      N      shear force along x / y
``in_contact``          1      1 where something touches the pad, 0 where nothing does
======================  =====  =====================================================================

Other names are allowed when they end in a unit suffix (``_mm``, ``_n``, ``_rad``): a stage's ``z_mm`` stays
``z_mm``. Label columns in gram-force or kilogram-force (``force_gf``, ``force_kgf``) become newtons
(``force_n``) on import (:func:`target_from_label`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from tactile_manip.errors import DatasetError

STANDARD_TARGETS = ("x_mm", "y_mm", "depth_mm", "force_n", "shear_x_n", "shear_y_n", "in_contact")
CONTACT_FLAG = "in_contact"
TARGET_UNITS = {"_mm": "mm", "_n": "N", "_rad": "rad"}   # suffix -> unit of a target name
GRAVITY_MPS2 = 9.80665                                    # standard gravity: 1 gf = 9.80665e-3 N
LABEL_TO_NEWTON = {"_gf": GRAVITY_MPS2 * 1e-3, "_kgf": GRAVITY_MPS2}  # label suffixes converted on import


def target_unit(name: str) -> str:
    """The unit of target ``name`` from its suffix ("1" for the ``in_contact`` flag).

    Raises:
        DatasetError: a name without a unit suffix.
    """
    if name == CONTACT_FLAG:
        return "1"
    for suffix, unit in TARGET_UNITS.items():
        if name.endswith(suffix) and len(name) > len(suffix):
            return unit
    raise DatasetError(f"target {name!r} has no unit suffix: name it like {', '.join(STANDARD_TARGETS)} "
                       f"(a target ends in {', '.join(TARGET_UNITS)}, or is {CONTACT_FLAG!r})")


def check_target_names(names: Sequence[str]) -> tuple[str, ...]:
    """``names`` as a tuple after checking each has a unit and none repeats (DatasetError otherwise)."""
    out = tuple(str(n) for n in names)
    for n in out:
        target_unit(n)
    twice = sorted({n for n in out if out.count(n) > 1})
    if twice:
        raise DatasetError(f"targets {twice} are named more than once")
    return out


def check_targets(targets: np.ndarray, names: tuple[str, ...], n: int,
                  unlabelled: np.ndarray | None = None) -> np.ndarray:
    """(n, K) float32 targets after checking shape, finiteness and the 0/1 contact flag; rows flagged in
    ``unlabelled`` (n,) bool hold NaN (their labels were held back) and are not checked."""
    t = np.asarray(targets)
    if t.ndim != 2 or t.shape != (n, len(names)):
        raise DatasetError(f"targets: expected shape ({n}, {len(names)}) for {list(names)}, got {t.shape}")
    if not (np.issubdtype(t.dtype, np.floating) or np.issubdtype(t.dtype, np.integer)):
        raise DatasetError(f"targets: expected real numbers, got dtype {t.dtype}")
    t = t.astype(np.float32, copy=False)
    bad = ~np.isfinite(t)
    if unlabelled is not None and unlabelled.any():
        bad[unlabelled] = False
    if bad.any():
        row, col = (int(i) for i in np.argwhere(bad)[0])
        raise DatasetError(f"targets: {int(bad.sum())} NaN or infinite values (first: {names[col]!r} of sample {row})")
    if CONTACT_FLAG in names:
        flag = t[:, names.index(CONTACT_FLAG)]
        if unlabelled is not None:
            flag = flag[~unlabelled]
        if not np.isin(flag, (0.0, 1.0)).all():
            raise DatasetError(f"targets: {CONTACT_FLAG!r} must be 0 or 1, got values such as "
                               f"{sorted(set(flag[~np.isin(flag, (0.0, 1.0))].tolist()))[:3]}")
    return t


def target_from_label(column: str) -> tuple[str, float]:
    """The target name and the factor to it from a label column: ``force_gf`` -> (``force_n``, 9.80665e-3).

    Columns in mm, N or rad keep their name (factor 1); ``in_contact`` stays a 0/1 flag.

    Raises:
        DatasetError: a column whose unit is not known (no suffix ``_mm``, ``_n``, ``_gf``, ``_kgf``, ``_rad``).
    """
    for suffix, factor in LABEL_TO_NEWTON.items():
        if column.endswith(suffix) and len(column) > len(suffix):
            return column[: -len(suffix)] + "_n", factor
    try:
        target_unit(column)
    except DatasetError:
        raise DatasetError(f"label column {column!r} has no unit this package knows: a target column ends in "
                           f"_mm, _n, _gf, _kgf or _rad (or is {CONTACT_FLAG!r})") from None
    return column, 1.0
