"""Labels for a pad's unlabelled presses from its twin: simulated presses of a board fitted to that pad, read
backwards, and corrected by whatever real labels there are.

A twin (a board file fitted to one real pad, ``tactile-manip fit-board``) pressed in the simulator gives a bank of
presses whose place, depth and force are known (``tactile-manip simulate --board fitted.toml``). Each real reading
is placed where the bank's readings most like it were made: the inverse-distance mean of the targets of its
``neighbours`` nearest bank presses, the distance taken between the readings' directions (unit vectors over the
channels: where the press is, whatever its depth) and, weighed by ``norm_weight``, their log field norms (how
hard). The places are then refitted on a smooth model of the real readings (:func:`refined_places`, no label: the
twin's layout of the pad at large kept, the scatter its detail leaves taken out; on the eFlesh spatial run 2.67 to
1.76 mm). With no label at all (:func:`twin_labels` with nothing labelled) that is every press's label: places in
the pad frame of the board file, which a rig's frame may turn and shift.

With labelled presses, the twin's answer is the start and the labels correct it, each correction chosen by its
leave-one-out error on the labels (at most ``LOO_MOST`` of them held out in turn):

- a place (``x_mm``, ``y_mm``, both labelled together) from the twin's place through the rig's frame: the best of
  the 8 quarter turns and mirror images of the axes plus an offset; or an affine map of the twin's place; or that
  affine map plus a Gaussian-kernel ridge correction (three widths), which bends the twin's layout onto the labels
  where the twin is off. Those places start the few-label recipe's refit on the field model beside the starts of
  its maps of the readings (:func:`~tactile_manip.learning.contact.fewlabel.pseudo_labels` with ``start``), the
  share of each chosen with the passes by leave-one-out on the labels (eFlesh spatial run, a twin fitted without
  labels, seeds 0 and 1: 10 labels 1.86 and 1.93 mm against 2.69 and 2.70 for the maps alone; 25 labels 1.26 and
  1.06 against 1.14 and 1.18);
- a load (``force_n``, ``depth_mm``) by one fit, not a choice among routes: the field-norm fit of
  :mod:`~tactile_manip.learning.contact.fewlabel` with the twin's load as one more shrunk term, so the labels say
  how much the twin adds. A choice by leave-one-out among the twin's load alone, the norm's fit with it and the
  norm's fit alone picked by the luck of 25 labels: on the eFlesh normal run (a twin fitted on 25 labels, its stage
  z standing in for the force) the fit's answers on the run's last 20 % were 0.598 N off over 20 draws that way,
  0.529 N with the one fit, 0.539 N with the norm's fit alone.

The bank may be any set of presses with those targets in the pad's reading layout: a twin's simulated presses, or
(to bound what a perfect twin would give) readings a smooth map of the real probe pose predicts.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from tactile_manip.errors import DatasetError
from tactile_manip.learning.contact.field_inverse import places_by_pass
from tactile_manip.learning.contact.fewlabel import (LOAD_TARGETS, MIN_LABELLED, PLACE_TARGETS, RBF_ALPHA, RBF_WIDTHS,
                                                     PseudoLabels, _loo_rmse, _norm_fit, _principal_axes, pseudo_labels)

NEIGHBOURS = 8        # bank presses whose targets place a reading
NORM_WEIGHT = 0.5     # weight of the log field norm beside the reading's direction in the bank distance
LOO_MOST = 200        # labelled presses held out in turn to choose a correction
LOAD_PROXIES = ("force_n", "depth_mm", "z_mm")  # what of the twin's stands for a load it does not give in newtons
                                                # (a twin of a rig's log places its presses by the stage's pose)
RIDGE = 1e-6          # of the affine fits
CORRECTION_WIDTHS_MM = (5.0, 10.0, 20.0)  # widths of the smooth correction of the twin's readings tried (none, too)
CORRECTION_ALPHA = 0.1              # its ridge, on residuals relative to the field norm
CORRECTION_LOO = 25                 # labelled presses held out in turn to choose its width
TURNS = tuple(np.array(m, float) for m in (
    [[1, 0], [0, 1]], [[0, -1], [1, 0]], [[-1, 0], [0, -1]], [[0, 1], [-1, 0]],
    [[1, 0], [0, -1]], [[-1, 0], [0, 1]], [[0, 1], [1, 0]], [[0, -1], [-1, 0]]))

PlaceFit = Callable[[np.ndarray, np.ndarray], np.ndarray]  # (labelled mask, (N, 2) labels) -> (N, 2) places


def bank_features(readings: np.ndarray, live: np.ndarray, norm_weight: float = NORM_WEIGHT) -> np.ndarray:
    """(N, C + 1) what the bank distance compares: the unit vector of each reading's ``live`` channels (N, ...)
    and ``norm_weight`` times its log field norm (uT)."""
    x = np.asarray(readings, np.float64).reshape(len(readings), -1)[:, live]
    norm = np.maximum(np.linalg.norm(x, axis=1), 1e-9)
    return np.hstack([x / norm[:, None], norm_weight * np.log(norm)[:, None]])


def twin_targets(readings: np.ndarray, bank_readings: np.ndarray, bank_targets: np.ndarray, *,
                 neighbours: int = NEIGHBOURS, norm_weight: float = NORM_WEIGHT) -> np.ndarray:
    """(N, K) each reading's targets read backwards from the bank: the inverse-distance mean of the ``bank_targets``
    (M, K) of its ``neighbours`` nearest ``bank_readings`` (M, ...) in :func:`bank_features`. The channels are the
    ones that vary among the bank's readings."""
    from scipy.spatial import cKDTree

    bank = np.asarray(bank_readings, np.float64).reshape(len(bank_readings), -1)
    live = bank.std(axis=0) > 0
    if len(bank) < neighbours:
        raise DatasetError(f"the twin's bank holds {len(bank)} presses; reading a press backwards needs at least "
                           f"{neighbours}")
    dist, idx = cKDTree(bank_features(bank, live, norm_weight)).query(
        bank_features(readings, live, norm_weight), k=neighbours)
    w = 1.0 / np.maximum(dist, 1e-9)
    return np.einsum("nk,nkt->nt", w, np.asarray(bank_targets, np.float64)[idx]) / w.sum(axis=1)[:, None]


def twin_labels(readings: np.ndarray, targets: np.ndarray, labelled: np.ndarray, *, bank_readings: np.ndarray,
                bank_targets: np.ndarray, names: Sequence[str], bank_names: Sequence[str],
                earlier: np.ndarray | None = None, weights: np.ndarray | None = None,
                neighbours: int = NEIGHBOURS, norm_weight: float = NORM_WEIGHT, refine: bool = True,
                map_neighbours: int = 20, stages: Callable[..., Any] | None = None) -> PseudoLabels:
    """Label every row of ``readings`` (N, ...) from the twin's bank and the rows where ``labelled`` (N,) holds.

    ``targets`` (N, K) named ``names`` is read on the labelled rows only; every name must be among the bank's
    ``bank_names`` (its targets (M, len(bank_names))), but for a load the bank lacks, which the labels then fit
    from the first of ``LOAD_PROXIES`` the bank has (a twin that places its presses by a rig's stage pose gives the
    stage's z, not the force). ``earlier`` and ``weights``: as for
    :func:`~tactile_manip.learning.contact.fewlabel.pseudo_labels` (the field norm's change, the labels' weights
    in the norm's fit). Without labelled rows the twin's answer is every label and the leave-one-out RMSE is NaN;
    with ``refine`` its places (one or two place targets) are then refitted on a smooth model of the real field
    (:func:`refined_places`). With labels and ``refine``, the twin's places (two place targets), refitted so and
    brought into the labels' frame by the correction of least leave-one-out error, start the few-label recipe's
    refit beside its maps (:func:`~tactile_manip.learning.contact.fewlabel.pseudo_labels` with ``start``), which
    weighs them by the leave-one-out on the labels (``map_neighbours``: the neighbours of its maps; with no more
    rows than that, the corrected places are the labels); ``stages`` shows its progress as there.
    Raises ``DatasetError`` for a target the bank lacks, readings of another layout than the bank's, non-finite
    readings, labels or bank, or one or two labelled rows (too few for a correction, too many to ignore).
    """
    x = np.asarray(readings, np.float64).reshape(len(readings), -1)
    bank = np.asarray(bank_readings, np.float64).reshape(len(bank_readings), -1)
    y = np.asarray(targets, np.float64).reshape(len(readings), -1)
    lab = np.asarray(labelled, bool)
    proxy = next((n for n in LOAD_PROXIES if n in bank_names), None)
    sources = [n if n in bank_names or n not in LOAD_TARGETS or proxy is None else proxy for n in names]
    missing = [n for n in sources if n not in bank_names]
    if missing:
        raise DatasetError(f"the twin's bank has no target {', '.join(missing)} (it has {', '.join(bank_names)})")
    if not lab.any() and sources != list(names):
        raise DatasetError(f"the twin gives no {', '.join(n for n, s in zip(names, sources) if n != s)} of its own "
                           f"(its bank has {', '.join(bank_names)}): label a few presses to fit it from the twin's "
                           f"{proxy}")
    if x.shape[1] != bank.shape[1]:
        raise DatasetError(f"readings of {x.shape[1]} values against the twin's bank of {bank.shape[1]}: simulate "
                           "the bank on the board the presses were imported with")
    if not (np.isfinite(x).all() and np.isfinite(y[lab]).all()):
        raise DatasetError("the readings and the labels must be finite to be placed on the twin")
    if not (np.isfinite(bank).all() and np.isfinite(np.asarray(bank_targets, np.float64)).all()):
        raise DatasetError("the twin's bank holds a NaN or infinite reading or target: simulate it again")
    if 0 < lab.sum() < 3:
        raise DatasetError(f"{int(lab.sum())} labelled press(es): the twin's correction needs 3 or more (or none)")
    cols = [list(bank_names).index(n) for n in sources]
    places = [k for k, n in enumerate(names) if n in PLACE_TARGETS]
    corrected, corrected_loo = "", 0.0
    if len(places) == 2 and lab.sum() >= 5 and "z_mm" in bank_names:
        bank_places = np.asarray(bank_targets, np.float64)[:, [list(bank_names).index(names[k]) for k in places]]
        if in_labels_frame(twin_targets(x[lab], bank, bank_places, neighbours=neighbours, norm_weight=norm_weight),
                           y[lab][:, places]):
            bank, corrected, corrected_loo = _corrected_bank(x, bank, bank_places, y[:, places], lab, neighbours,
                                                             norm_weight)
    twin = twin_targets(x, bank, np.asarray(bank_targets, np.float64)[:, cols], neighbours=neighbours,
                        norm_weight=norm_weight)
    values, loo, methods = twin.copy(), np.full(len(names), np.nan), ["twin"] * len(names)
    if not lab.any():
        if refine and len(places) in (1, 2):
            values[:, places] = refined_places(x, twin[:, places])
            methods = ["twin, refined on the field model" if k in places else m
                       for k, m in enumerate(methods)]
        return PseudoLabels(values=values, loo_rmse=loo, methods=tuple(methods))
    if len(places) == 2:
        yp = y[:, places]
        start = refined_places(x, twin[:, places]) if refine else twin[:, places]
        err, name, fit = min(((_place_loo(fit, yp, lab), name, fit) for name, fit in _place_fits(start)),
                             key=lambda t: t[0])
        what = f"twin place{corrected}{', refitted' if refine else ''}, {name}"
        if refine and lab.sum() >= MIN_LABELLED and len(x) > map_neighbours:
            found = pseudo_labels(x, yp, lab, names=[names[k] for k in places], stages=stages,
                                  neighbours=map_neighbours,
                                  start=(f"the {what}", [(lambda keep, _, k=k: fit(keep, yp)[:, k]) for k in range(2)]))
            values[:, places] = found.values
            loo[places] = np.maximum(found.loo_rmse, corrected_loo)
            methods = [found.methods[places.index(k)] if k in places else m for k, m in enumerate(methods)]
        else:
            values[:, places] = fit(lab, yp)
            # the correction of the readings saw every label: its own leave-one-out error bounds the place's from
            # below
            loo[places] = max(err, corrected_loo)
            methods = [what if k in places else m for k, m in enumerate(methods)]
    for k in (k for k in range(len(names)) if k not in places or len(places) != 2):
        name, fit = _load_fit(x, twin[:, k], earlier, weights, labelled=lab)
        err = _loo_rmse(fit, y[:, k], lab)
        values[:, k] = fit(lab, y[:, k])
        loo[k] = err
        methods[k] = name if sources[k] == names[k] else name.replace("twin load", f"twin's {sources[k]}")
    values[lab] = y[lab]
    return PseudoLabels(values=values, loo_rmse=loo, methods=tuple(methods))


def frame_rmse(placed: np.ndarray, labels: np.ndarray, turns: Sequence[np.ndarray] = TURNS) -> float:
    """2-D RMSE of ``placed`` against ``labels`` (N, 2) after the best of ``turns`` (2x2 each; default the 8
    quarter turns and mirror images of the axes) and an offset, both fitted on these rows."""
    a, b = np.asarray(placed, np.float64), np.asarray(labels, np.float64)
    return min(float(np.sqrt(np.mean(np.sum((a @ t.T - (a @ t.T).mean(0) - (b - b.mean(0))) ** 2, axis=1))))
               for t in turns)


def in_labels_frame(placed: np.ndarray, labels: np.ndarray) -> bool:
    """Whether a twin's ``placed`` (K, 2) places of the labelled presses are in the frame of their ``labels`` (K, 2):
    as near them as they are (RMS) within 1.5 times what the best quarter turn or mirror of the axes and an offset
    leave. A twin fitted to the readings alone lives in its board file's pad frame, which a rig's frame may turn
    and shift; its readings can then not be corrected at the labels' places."""
    a, b = np.asarray(placed, np.float64), np.asarray(labels, np.float64)
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1)))) <= 1.5 * frame_rmse(a, b) + 1e-9


def refined_places(readings: np.ndarray, places: np.ndarray, fitted: np.ndarray | None = None) -> np.ndarray:
    """(N, P) the twin's ``places`` (N, P) of ``readings`` (N, ...), with no label, refitted on a smooth model of
    the real field: :func:`~tactile_manip.learning.contact.field_inverse.places_by_pass` from the twin's places,
    after its last pass. The twin's field misses the real one in detail, and a reading read backwards on it lands
    where the twin's detail, not the pad's, is like it; a model fitted on the real readings at those places keeps
    the twin's layout of the pad at large and takes out the scatter of its detail. ``fitted`` (N,) bool: the rows
    the models are fitted on (default: every row); the others, such as a run's test presses, are only placed.
    Where too few rows are fitted for the models, the places come back as they are."""
    x = np.asarray(readings, np.float64).reshape(len(readings), -1)
    return places_by_pass(x, places, np.zeros(len(x), bool), fitted=fitted)[-1]


def _corrected_bank(x: np.ndarray, bank: np.ndarray, bank_places: np.ndarray, y: np.ndarray, lab: np.ndarray,
                    neighbours: int, norm_weight: float) -> tuple[np.ndarray, str, float]:
    """The bank's readings (M, D) corrected by the labelled presses, where the bank's presses are placed in the
    labels' frame (a twin of stage poses): at each labelled press, the twin's reading at its place (the bank press
    nearest it in place whose reading is nearest its own, over depth) misses the real one by a residual; a
    Gaussian-kernel ridge of those residuals, relative to the field norm, over the place, scaled by each bank
    press's norm, is added to the bank. The width (or none) of least leave-one-out place error on the labels;
    the name of what was done ("" for none) and that leave-one-out RMSE (per coordinate)."""
    from scipy.spatial import cKDTree

    rows = np.flatnonzero(lab)
    near = cKDTree(bank_places).query(y[rows], k=min(60, len(bank)))[1]
    best = near[np.arange(len(rows)), np.argmin(((bank[near] - x[rows, None]) ** 2).sum(-1), axis=1)]
    norm = np.maximum(np.linalg.norm(bank, axis=1), 1e-9)
    rel = (x[rows] - bank[best]) / norm[best, None]
    places = y[rows]

    def corrected(width: float | None, keep: np.ndarray) -> np.ndarray:
        if width is None:
            return bank
        p = places[keep]
        k = np.exp(-((p[:, None] - p[None]) ** 2).sum(-1) / (2 * width ** 2))
        w = np.linalg.solve(k + CORRECTION_ALPHA * np.eye(len(p)), rel[keep])
        kb = np.exp(-((bank_places[:, None] - p[None]) ** 2).sum(-1) / (2 * width ** 2))
        return bank + norm[:, None] * (kb @ w)

    errs = {}
    held = np.unique(np.linspace(0, len(rows) - 1, min(len(rows), CORRECTION_LOO)).round().astype(int))
    for width in (None, *CORRECTION_WIDTHS_MM):
        miss = []
        for i in held:
            keep = np.arange(len(rows)) != i
            placed = twin_targets(x[rows[i:i + 1]], corrected(width, keep), bank_places, neighbours=neighbours,
                                  norm_weight=norm_weight)
            miss.append(placed[0] - places[i])
        errs[width] = float(np.sqrt(np.mean(np.square(miss))))
    width = min(errs, key=errs.get)
    if width is None:  # nothing corrected: nothing to bound the places' own leave-one-out error with
        return bank, "", 0.0
    return corrected(width, np.ones(len(rows), bool)), f" (readings corrected, {width:g} mm)", errs[width]


def _place_fits(twin: np.ndarray) -> list[tuple[str, PlaceFit]]:
    """The corrections of the twin's places (N, 2) on the labels, by name."""
    z = (twin - twin.mean(axis=0)) / max(float(twin.std()), 1e-9)
    a = np.hstack([np.ones((len(z), 1)), z])

    def turned(lab: np.ndarray, y: np.ndarray) -> np.ndarray:
        best = min((float(np.sum((y[lab] - y[lab].mean(0) - (twin[lab] - twin[lab].mean(0)) @ t.T) ** 2)), i)
                   for i, t in enumerate(TURNS))
        t = TURNS[best[1]]
        return twin @ t.T + (y[lab].mean(0) - twin[lab].mean(0) @ t.T)

    def affine(lab: np.ndarray, y: np.ndarray) -> np.ndarray:
        al = a[lab]
        return a @ np.linalg.solve(al.T @ al + RIDGE * np.eye(3), al.T @ y[lab])

    def kernel(gamma: float) -> PlaceFit:
        def fit(lab: np.ndarray, y: np.ndarray) -> np.ndarray:
            base = affine(lab, y)
            zl = z[lab]
            k = np.exp(-gamma * ((zl[:, None] - zl[None]) ** 2).sum(-1))
            w = np.linalg.solve(k + RBF_ALPHA * np.eye(len(zl)), y[lab] - base[lab])
            return base + np.exp(-gamma * ((z[:, None] - zl[None]) ** 2).sum(-1)) @ w
        return fit

    return [("turn and offset", turned), ("affine", affine),
            *((f"affine + kernel {g:g}", kernel(g)) for g in RBF_WIDTHS)]


def _place_loo(fit: PlaceFit, y: np.ndarray, lab: np.ndarray) -> float:
    """Leave-one-out RMSE (per coordinate, the root of the mean over both) of a place fit on the labelled rows."""
    rows = np.flatnonzero(lab)
    rows = rows[np.unique(np.linspace(0, len(rows) - 1, min(len(rows), LOO_MOST)).round().astype(int))]
    errs = []
    for i in rows:
        keep = lab.copy()
        keep[i] = False
        errs.append(fit(keep, y)[i] - y[i])
    err = float(np.sqrt(np.mean(np.square(errs))))
    return err if np.isfinite(err) else np.inf


def _load_fit(x: np.ndarray, twin: np.ndarray, earlier: np.ndarray | None, weights: np.ndarray | None, *,
              labelled: np.ndarray) -> tuple[str, Callable]:
    """The fit of a load target on the labels: the field norm's shrunk fit (the ``labelled`` rows set its knots)
    with the twin's load (N,) as one more shrunk term."""
    live = x.std(axis=0) > 0
    xs = x[:, live]
    norm = np.linalg.norm(xs, axis=1)
    before = None if earlier is None else np.asarray(earlier, np.float64).reshape(len(x), -1)[:, live]
    change = None if before is None else norm - np.linalg.norm(before, axis=1)
    axes = _principal_axes((xs - xs.mean(axis=0)) / xs.std(axis=0), 3)[:, 1:]
    scaled_twin = (twin - twin.mean()) / max(float(twin.std()), 1e-12)
    name, fit = _norm_fit(norm, change, np.hstack([axes, scaled_twin[:, None]]), weights, labelled=labelled)
    return name.replace("reading axes 2-3", "reading axes 2-3 and the twin load"), fit


def check_bank_targets(names: Sequence[str]) -> None:
    """Refuse (DatasetError) target names the twin does not give: places and loads only."""
    other = [n for n in names if n not in PLACE_TARGETS + LOAD_TARGETS]
    if other:
        raise DatasetError(f"the twin labels places ({', '.join(PLACE_TARGETS)}) and loads "
                           f"({', '.join(LOAD_TARGETS)}), not {', '.join(other)}")
