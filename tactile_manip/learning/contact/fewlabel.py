"""Labels for the unlabelled presses of a dataset, from a handful of labelled ones and the shape of the readings.

A probe rig gives a few labelled presses; pressing the pad by hand, or the rig run without its load cell or stage
log, gives thousands of unlabelled readings. The readings of a pad lie on a low-dimensional surface (a press has
a position, a depth and little else), and neighbouring readings on that surface are neighbouring presses. This
module maps that surface (Isomap: graph distances between each reading and its nearest neighbours, laid out by
classical scaling from landmark readings) and fits each target from the labelled presses alone. A place
(``PLACE_TARGETS``) is fitted on the maps, a load (``LOAD_TARGETS``) on the field norm, any other target on
either, the fit chosen by leave-one-out error on the labels:

- on the maps: an affine map of the 2 or 3 leading map coordinates, alone or plus a Gaussian-kernel ridge
  correction (three widths);
- on the field norm: one fit of the reading's field norm, which follows depth and force at a fixed place: a line
  in the norm that bends at knots (``NORM_KNOTS``: one per ``LABELS_PER_KNOT`` labelled presses, at quantiles of
  every reading's norm, labelled or not, so the bends sit where the presses are), with the second and third
  principal axes of the standardised readings (how the field's pattern, not only its size, moves as the elastomer
  is loaded) and, where the readings come with the frames before them, the norm's change since the oldest of those
  frames, alone and times the norm (an elastomer gives less force for the same field while it is pressed in than
  while it springs back, and the sign and speed of that change say which). On the eFlesh normal run the force
  against the norm is nearly straight with one soft bend, which a cubic follows badly where the labels are few:
  over 40 draws of 25 labels the fit's answers on the run's last 20 % were 0.635 N off with a cubic and 0.568 N
  with the bent line, closer in 75 % of the draws (``python -m benchmarks.force_limit``; 10 labels about even,
  0.88 N; 100 labels, eight knots, 0.44 against 0.40 N).
  Every term but the norm's linear one is shrunk by a ridge; the fits of several ridge weights are averaged,
  each weighted by how well it holds out on the labels (leave-one-out). Where the presses come with times, the
  later labelled presses can weigh more (:func:`recency_weights`): a skin softens as it is pressed, so the force
  for a given field drifts down over a run, and the presses a model meets next are most like the latest ones.
  The simpler fits of the norm are special cases of this one; offered beside it, they were chosen by the luck of
  the draw more than by their fit (on the eFlesh normal run, 30 draws of 25 labels: 0.76 N against 0.71 N), as
  were the maps' fits for the force.

Three maps are tried: two of the reading's direction (the unit vector of all channels: the press position, whatever
its depth), one with each graph edge measured in units of the local spacing of the readings (as if the presses were
spread evenly over the pad), and one of the standardised reading. The chosen fits label every unlabelled training
row (:func:`pseudo_labels`); the places among them (one or two named place targets) are then refitted on a smooth
model of the field (:mod:`~tactile_manip.learning.contact.field_inverse`), which takes out the map's local scatter,
in up to six passes, coarse to fine, as many as give the least leave-one-out error on the labels (on the eFlesh
spatial run, 25 labels, from the map fit of least leave-one-out error: 2.13 to 1.57 mm over 16 draws after six
passes, 1.64 mm after three). The refit starts from several first placings and takes the mean of where they lead: on
every map whose best fits are about as good as the best map's (``START_SPREAD``), the best and the next best fit per
coordinate. Each start leaves its own smooth bend between the labels, and the bends partly cancel (same run and
labels, six passes: 1.57 to 1.48 mm over those 16 draws, closer in 12, and 1.62 to 1.47 mm over 24 draws not used
for any choice, closer in 20; with three passes 1.64 to 1.55 and 1.69 to 1.55 mm; the map of the standardised
reading fits 2-3 times worse there and starts none). Where the leave-one-out keeps one of the finer passes that
settling repeats (four passes or more), each start runs all six and its places then settle
(:func:`~tactile_manip.learning.contact.field_inverse.settle`: the finer passes repeated with the places shaken,
which takes out much of the bend the passes keep between the labels) before the mean is taken.
The contact network then trains on them (``unlabelled = "manifold"`` in a contact training config). The
leave-one-out RMSE of the chosen fit travels with the labels: the network's sigma is widened by it, since the
network cannot be more exact than the labels it learnt from.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from tactile_manip.errors import DatasetError
from tactile_manip.progress import progress_bar
from tactile_manip.learning.contact.field_inverse import SETTLE_PASSES, places_by_pass, settle

MIN_LABELLED = 5          # below this, no fit is chosen by leave-one-out
LANDMARKS = 1500          # readings whose graph distances to all others lay out the map
MAP_DIMS = 3              # map coordinates kept
RBF_WIDTHS = (0.3, 1.0, 3.0)  # gamma of the kernel correction, on map coordinates of unit spread
RBF_ALPHA = 0.1           # ridge of the kernel correction
RIDGE = 1e-6              # ridge of the affine and polynomial fits
SHRINK = (0.0, 0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0)  # ridge weights of the shrunk fit, on unit-spread terms
NORM_KNOTS = (2, 8)       # fewest and most knots of the field norm's bent line
LABELS_PER_KNOT = 12      # labelled presses per knot of that line (between those bounds)
REFINED_LOO = 25          # labelled presses held out in turn for the refitted places' leave-one-out RMSE
START_SPREAD = 1.5        # a map starts the refit if its fits' leave-one-out error is within this of the best one's
STARTS_PER_MAP = 2        # fits per such map that start the refit: the best and the next best per coordinate
PRIOR_SHARES = (0.0, 1 / 3, 0.5, 2 / 3, 1.0)  # shares of a start from elsewhere (a twin) in the refit's places
PLACE_TARGETS = ("x_mm", "y_mm")        # where the press is: fitted on the maps only
LOAD_TARGETS = ("force_n", "depth_mm")  # how hard it is: fitted on the field norm only


@dataclass(frozen=True)
class PseudoLabels:
    """Targets (N, K) for every row given (labelled rows keep their labels), the leave-one-out RMSE (K,) of each
    target's chosen fit on the labelled rows, and that fit's name per target."""

    values: np.ndarray
    loo_rmse: np.ndarray
    methods: tuple[str, ...]


def pseudo_labels(readings: np.ndarray, targets: np.ndarray, labelled: np.ndarray, *, neighbours: int = 20,
                  earlier: np.ndarray | None = None, names: Sequence[str] | None = None,
                  maps: dict[str, np.ndarray] | None = None, refine: bool = True,
                  weights: np.ndarray | None = None, stages: Callable[..., Any] | None = None,
                  start: tuple[str, Sequence[Fit]] | None = None) -> PseudoLabels:
    """Label every row of ``readings`` (N, ...) from the rows where ``labelled`` (N,) holds.

    ``targets`` (N, K) is read only on the labelled rows. ``earlier`` (N, ...): the reading a few frames before
    each one in its stream (the reading itself where there is none), which adds the field norm's change to the
    norm's fit. ``names`` (K,): the targets' names; a place (``PLACE_TARGETS``) is fitted on the maps only and a
    load (``LOAD_TARGETS``) on the field norm only, any other target (or every one, without names) on whichever
    fit has the lowest leave-one-out error. ``maps``: :func:`reading_maps` of the same readings and
    ``neighbours``, where the caller has them (they depend on the readings alone, so several draws of labels on
    one set of readings can share them). ``refine``: the places (one or two place targets, named) are refitted from
    a smooth model of the field (:func:`~tactile_manip.learning.contact.field_inverse.places_by_pass`) in as many
    passes as give the least leave-one-out RMSE, and their leave-one-out RMSE is that of the refitted places.
    ``weights`` (N,): how much each labelled row counts in the fit of the field norm (:func:`recency_weights`: the
    later presses of a run more, where the skin drifts); read on the labelled rows only, which must hold finite
    positive weights. ``stages``: makes the progress display of each stage, given the keywords ``total``,
    ``desc`` and ``unit`` (:func:`~tactile_manip.progress.progress_bar`; default: nothing shown): the maps, the
    fits' leave-one-out, the refit's leave-one-out (one step per held-out press and start: most of the time) and
    the placing. ``start``: one more first placing of the places, from elsewhere (a twin's places brought into the
    labels' frame: :mod:`~tactile_manip.learning.contact.twin_prior`), as its name and a fit per place target; the
    refit from it and the refit from the maps' starts are blended, the share of each (``PRIOR_SHARES``) and the
    number of passes chosen together by the leave-one-out. Raises ``DatasetError`` with fewer than
    ``MIN_LABELLED`` labelled rows, a non-finite label or
    reading, fewer rows than ``neighbours`` + 1, names that do not match the targets, maps with other rows than the
    readings, or weights of another length or not finite and positive on the labelled rows.
    """
    x = np.asarray(readings, np.float64).reshape(len(readings), -1)
    y = np.asarray(targets, np.float64).reshape(len(readings), -1)
    lab = np.asarray(labelled, bool)
    if lab.sum() < MIN_LABELLED:
        raise DatasetError(f"{int(lab.sum())} labelled press(es): the unlabelled presses need at least "
                           f"{MIN_LABELLED} labelled ones to be placed on the map")
    if not np.isfinite(y[lab]).all():
        raise DatasetError("a labelled press has a NaN or infinite target")
    if not np.isfinite(x).all():
        raise DatasetError("a reading is NaN or infinite: the map of the readings needs finite readings")
    if names is not None and len(names) != y.shape[1]:
        raise DatasetError(f"{len(names)} target name(s) for {y.shape[1]} target(s)")
    if len(x) <= neighbours:
        raise DatasetError(f"{len(x)} presses: the map of the readings needs more than {neighbours}")
    if maps is not None and any(np.shape(m)[:1] != (len(x),) for m in maps.values()):
        raise DatasetError(f"maps of {sorted({len(m) for m in maps.values()})} rows given for {len(x)} readings")
    if weights is not None:
        weights = np.asarray(weights, np.float64)
        if weights.shape != (len(x),) or not (np.isfinite(weights[lab]) & (weights[lab] > 0)).all():
            raise DatasetError(f"label weights of shape {weights.shape} for {len(x)} rows: each labelled row needs "
                               f"a finite positive weight")
        weights = np.where(lab, weights, 1.0) if np.ptp(weights[lab]) > 0 else None  # equal weights weigh nothing
    varies = x.std(axis=0) > 0
    x = x[:, varies]
    norm = np.linalg.norm(x, axis=1)
    change = None
    if earlier is not None:
        before = np.asarray(earlier, np.float64).reshape(len(readings), -1)
        if before.shape[1] != varies.size or not np.isfinite(before).all():
            raise DatasetError("the earlier frames must be finite readings of the same shape as the readings")
        change = norm - np.linalg.norm(before[:, varies], axis=1)
    kinds = [None] * y.shape[1] if names is None else [
        "place" if n in PLACE_TARGETS else "load" if n in LOAD_TARGETS else None for n in names]
    fits = {}
    by_map: dict[str, list[tuple[str, Fit]]] = {}
    stages = stages or (lambda **kw: progress_bar(**kw, quiet=True))
    if any(kind != "load" for kind in kinds):
        if maps is None:
            with stages(total=len(MAPS), desc="labelling: mapping the readings", unit="map") as bar:
                maps = reading_maps(x, neighbours, bar=bar)
        by_map = _fits_by_map(maps)
        fits["place"] = [named for group in by_map.values() for named in group]
    if any(kind != "place" for kind in kinds):
        fits["load"] = [_norm_fit(norm, change, _principal_axes((x - x.mean(axis=0)) / x.std(axis=0), 3)[:, 1:],
                                  weights, labelled=lab)]
    values = np.empty((len(x), y.shape[1]))
    loo = np.empty(y.shape[1])
    methods = []
    scored: dict[tuple[int, int], float] = {}

    def score(fit: Fit, k: int) -> float:  # a fit's leave-one-out RMSE on target k, computed once
        if (id(fit), k) not in scored:
            scored[id(fit), k] = _loo_rmse(fit, y[:, k], lab)
        return scored[id(fit), k]

    with stages(total=y.shape[1], desc="labelling: each target's fit by leave-one-out", unit="target") as bar:
        for k, kind in enumerate(kinds):
            best = None
            for name, fit in fits[kind] if kind else [*fits["place"], *fits["load"]]:
                err = score(fit, k)
                if best is None or err < best[0]:
                    best = (err, name, fit)
            loo[k], name, fit = best
            values[:, k] = fit(lab, y[:, k])
            values[lab, k] = y[lab, k]
            methods.append(name)
            bar.update()
    places = [k for k, kind in enumerate(kinds) if kind == "place"]
    if refine and len(places) in (1, 2) and (~lab).any():
        groups = [_starts(by_map, places, score)] + ([[list(start[1])]] if start is not None else [])
        held = len(list(_held_out(lab, REFINED_LOO)))
        with stages(total=held * sum(map(len, groups)), desc="labelling: leave-one-out of the field model's refit",
                    unit="refit") as bar:
            errs = [_refined_errors(x, y[:, places], lab, group, bar=bar) for group in groups]  # (held, passes, P)
        shares = PRIOR_SHARES if start is not None else (0.0,)
        # the share of the other start and the passes of least leave-one-out error, the places of each blend being
        # the blend of each group's (so are their errors)
        by_share = [np.sqrt(np.mean(np.square(_blend(errs[0], errs[-1], w)), axis=0)) for w in shares]
        pick = int(np.argmin([np.min(np.sum(b ** 2, axis=1)) for b in by_share]))
        share, by_pass = shares[pick], by_share[pick]
        count = int(np.argmin(np.sum(by_pass ** 2, axis=1))) + 1  # the passes of least leave-one-out error
        # where the leave-one-out keeps a pass that settling repeats, the places run all the passes and settle; the
        # leave-one-out stays that of the passes alone (holding the settling out too would cost four times the
        # leave-one-out above)
        settles = count > len(by_pass) - len(SETTLE_PASSES)
        used = [(w, g) for w, g in zip((1.0 - share, share), groups) if w > 0]
        with stages(total=sum(len(g) for _, g in used), desc="labelling: placing the unlabelled presses",
                    unit="start") as bar:
            values[:, places] = sum(w * (_refit(x, y[:, places], lab, g, settled=True, bar=bar) if settles
                                         else _refit(x, y[:, places], lab, g, bar=bar)[count - 1]) for w, g in used)
        loo[places] = by_pass[count - 1]
        done = (f"{len(by_pass)} passes, settled (leave-one-out least after {count})" if settles
                else f"{count} pass{'es' if count > 1 else ''}")
        for k in places:
            if start is not None and share >= 1.0:  # the maps' starts held out worse: none of their fits is used
                methods[k] = f"{start[0]}, refined on the field model in {done} (the maps' starts held out worse)"
                continue
            blend = ("" if start is None else f", and {start[0]} at {share:.0%}" if share > 0
                     else f"; not {start[0]}, which held out worse")
            methods[k] += f", refined on the field model in {done} (mean of {len(groups[0])} starts{blend})"
    return PseudoLabels(values=values, loo_rmse=loo, methods=tuple(methods))


def recency_weights(times_s: np.ndarray, rate: float, groups: np.ndarray | None = None) -> np.ndarray:
    """Weights (N,) for the labelled presses of a run that drifts: ``e ** (rate * f)``, ``f`` the share of its
    run's time span (``groups``: the run of each row; one run without) elapsed at each row, from 0 at the run's
    first row to 1 at its last; divided by the largest. An elastomer softens as it is pressed, so the presses a
    model will meet next are most like the latest ones. ``rate`` 0 weighs every press alike."""
    t = np.asarray(times_s, np.float64)
    if t.ndim != 1 or not np.isfinite(t).all():
        raise DatasetError(f"recency weights need finite times, one per row; got shape {t.shape}")
    if not (np.isfinite(rate) and rate >= 0):
        raise ValueError(f"the recency rate must be finite and >= 0, got {rate}")
    runs = np.zeros(len(t), np.int64) if groups is None else np.asarray(groups)
    share = np.zeros(len(t))
    for g in np.unique(runs):
        rows = runs == g
        span = np.ptp(t[rows])
        share[rows] = (t[rows] - t[rows].min()) / span if span > 0 else 1.0
    return np.exp(rate * (share - 1.0))


MAPS = ("direction", "reading", "direction (even)")  # the maps of :func:`reading_maps`, in order


def reading_maps(readings: np.ndarray, neighbours: int = 20, *, bar: Any = None) -> dict[str, np.ndarray]:
    """The three maps (N, ``MAP_DIMS``) the labels are fitted on, by name (``MAPS``), of ``readings`` (N, D)
    whose every channel varies: Isomap of the reading's direction (its unit vector), of the standardised reading,
    and of the direction measured evenly (``isomap(..., even=True)``). ``bar``: a progress display, one step per
    map."""
    x = np.asarray(readings, np.float64)
    direction = x / np.maximum(np.linalg.norm(x, axis=1), 1e-12)[:, None]
    standard = (x - x.mean(axis=0)) / x.std(axis=0)
    maps = {}
    for name, points, even in zip(MAPS, (direction, standard, direction), (False, False, True)):
        maps[name] = isomap(points, neighbours, even=even)
        if bar is not None:
            bar.update()
    return maps


def isomap(points: np.ndarray, neighbours: int, dims: int = MAP_DIMS, *, even: bool = False) -> np.ndarray:
    """Isomap coordinates (N, dims) of ``points`` (N, D): shortest paths over the ``neighbours``-nearest graph
    from up to ``LANDMARKS`` evenly spaced landmark points, laid out by landmark classical scaling. Parts of the
    graph that no path joins are joined at the largest distance found. ``even``: each edge is measured in units
    of its ends' distances to their farthest neighbour, as if the points were spread evenly over the surface."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import shortest_path
    from scipy.spatial import cKDTree

    n = len(points)
    dist, idx = cKDTree(points).query(points, k=neighbours + 1)
    rows = np.repeat(np.arange(n), neighbours)
    if even:
        reach = np.maximum(dist[:, -1], 1e-12)
        dist = dist / np.sqrt(reach[:, None] * reach[idx])
    graph = csr_matrix((dist[:, 1:].ravel() + 1e-12, (rows, idx[:, 1:].ravel())), shape=(n, n))
    graph = graph.maximum(graph.T)
    marks = np.unique(np.linspace(0, n - 1, min(n, LANDMARKS)).round().astype(int))
    d = shortest_path(graph, directed=False, indices=marks)
    finite = np.isfinite(d)
    d[~finite] = 1.5 * d[finite].max()
    d2 = d ** 2
    dl = d2[:, marks]
    centred = -0.5 * (dl - dl.mean(axis=0) - dl.mean(axis=1)[:, None] + dl.mean())
    vals, vecs = np.linalg.eigh(centred)
    order = np.argsort(vals)[::-1][:dims]
    vals, vecs = np.maximum(vals[order], 1e-12), vecs[:, order]
    # every point from its distances to the landmarks (de Silva & Tenenbaum's triangulation)
    return (-0.5 * (d2 - dl.mean(axis=1)[:, None]).T @ (vecs / np.sqrt(vals)))


Fit = Callable[[np.ndarray, np.ndarray], np.ndarray]  # (labelled mask, target column) -> prediction per row


def _principal_axes(z: np.ndarray, count: int) -> np.ndarray:
    """The first ``count`` principal components (N, count) of the rows of ``z``, each of unit spread."""
    centred = z - z.mean(axis=0)
    _, _, vt = np.linalg.svd(centred, full_matrices=False)
    scores = centred @ vt[:count].T
    return scores / np.maximum(scores.std(axis=0), 1e-12)


def _fits_by_map(maps: dict[str, np.ndarray]) -> dict[str, list[tuple[str, Fit]]]:
    return {name: list(_map_fits(name, coords)) for name, coords in maps.items()}


def _map_fits(name: str, coords: np.ndarray) -> Iterator[tuple[str, Fit]]:
    z = coords / coords[:, :2].std()
    yield f"{name} map, affine in 2", _affine(z[:, :2])
    yield f"{name} map, affine in 3", _affine(z[:, :3])
    for gamma in RBF_WIDTHS:
        yield f"{name} map, affine + kernel {gamma:g}", _affine_kernel(z[:, :2], gamma)


def _norm_fit(norm: np.ndarray, change: np.ndarray | None, axes: np.ndarray,
              weights: np.ndarray | None = None, *, labelled: np.ndarray) -> tuple[str, Fit]:
    # The fits of the field norm nest: a bent line of the norm, its change, the readings' next principal axes.
    # Choosing among nested fits by leave-one-out on a handful of labels picks noise, so the norm is offered as
    # one fit holding every term, all but the norm's linear one shrunk by ridges averaged by leave-one-out.
    scaled = norm / max(float(norm.std()), 1e-12)
    knots = norm_knots(scaled, labelled)
    terms = [scaled[:, None], np.maximum(scaled[:, None] - knots[None], 0.0)]
    rate = change / change.std() if change is not None and change.std() > 0 else None  # loading or unloading
    if rate is not None:
        terms.append(np.stack([rate, rate * scaled], axis=1))
    shrunk = np.hstack([*terms, axes])
    return ((f"field norm, bent at {len(knots)} knot{'' if len(knots) == 1 else 's'}, + "
             + ("" if rate is None else "its change, ") + "reading axes 2-3, shrunk"
             + ("" if weights is None else ", later labels weighted")),
            _shrunk(shrunk / shrunk.std(axis=0).clip(1e-12), free=1, weights=weights))


def norm_knots(scaled: np.ndarray, labelled: np.ndarray) -> np.ndarray:
    """(B,) the knots of the field norm's bent line (its terms ``max(scaled - knot, 0)``): evenly spaced quantiles
    of ``scaled`` (N,), every row's norm (the unlabelled readings say where the presses lie), one per
    ``LABELS_PER_KNOT`` of the rows ``labelled`` (N,) holds, within ``NORM_KNOTS``; knots that coincide (readings
    at a few norms) count once. (Dropping a knot with fewer than 2 or 3 labelled norms beyond it did worse on
    synthetic presses with 5 to 12 labels: the shrinking already keeps such a bend small.)"""
    count = int(np.clip(int(np.asarray(labelled, bool).sum()) // LABELS_PER_KNOT, *NORM_KNOTS))
    return np.unique(np.quantile(scaled, np.linspace(0.0, 1.0, count + 2)[1:-1]))


def _design(z: np.ndarray) -> np.ndarray:
    return np.hstack([np.ones((len(z), 1)), z])


def _affine(z: np.ndarray) -> Fit:
    a = _design(z)

    def fit(lab: np.ndarray, y: np.ndarray) -> np.ndarray:
        al = a[lab]
        coef = np.linalg.solve(al.T @ al + RIDGE * np.eye(a.shape[1]), al.T @ y[lab])
        return a @ coef
    return fit


def _affine_kernel(z: np.ndarray, gamma: float) -> Fit:
    affine = _affine(z)

    def fit(lab: np.ndarray, y: np.ndarray) -> np.ndarray:
        base = affine(lab, y)
        zl = z[lab]
        k = np.exp(-gamma * ((zl[:, None] - zl[None]) ** 2).sum(-1))
        w = np.linalg.solve(k + RBF_ALPHA * np.eye(len(zl)), y[lab] - base[lab])
        out = np.empty(len(z))
        for s in range(0, len(z), 4096):  # the kernel to every row, in blocks
            out[s:s + 4096] = np.exp(-gamma * ((z[s:s + 4096, None] - zl[None]) ** 2).sum(-1)) @ w
        return base + out
    return fit


def _shrunk(z: np.ndarray, free: int, weights: np.ndarray | None = None) -> Fit:
    """Affine in ``z`` (N, D), every term after the first ``free`` shrunk by a ridge: the fits of every ridge
    weight in ``SHRINK``, averaged with weights that follow each one's leave-one-out error on the labelled rows
    (closed form: the residual over one less the leverage). A fit with leave-one-out mean square error ``e`` out of
    ``n`` labelled rows weighs ``e ** (-n / 2)``, the Gaussian likelihood of its held-out residuals, so a weight
    that holds out clearly better dominates, and weights that hold out alike share. Picking the one weight of
    least leave-one-out error instead picks by the luck of a handful of labels (on the eFlesh normal run, 100
    draws of 25 labels: the unlabelled presses 0.711 N off that way, 0.695 N averaged). ``weights`` (N,): each
    labelled row's weight in the least squares and in its leave-one-out error (weighted least squares: the rows and
    targets scaled by the root of the weight, relative to the labelled rows' mean weight)."""
    a = _design(z)
    penalty = np.ones(a.shape[1])
    penalty[:1 + free] = 0.0  # the intercept and the free terms are not shrunk

    def fit(lab: np.ndarray, y: np.ndarray) -> np.ndarray:
        root = np.ones(int(lab.sum())) if weights is None else np.sqrt(weights[lab] / weights[lab].mean())
        al, yl = a[lab] * root[:, None], y[lab] * root
        coefs, errs = [], []
        for weight in SHRINK:
            gram = al.T @ al + np.diag(weight * penalty + RIDGE)
            coef = np.linalg.solve(gram, al.T @ yl)
            leverage = np.einsum("ij,ji->i", al, np.linalg.solve(gram, al.T))
            coefs.append(coef)
            errs.append(float(np.mean(((yl - al @ coef) / np.maximum(1.0 - leverage, 1e-9)) ** 2)))
        errs = np.maximum(np.array(errs), 1e-300)  # an exact fit holds out perfectly, not at log(0)
        share = np.exp(-0.5 * len(yl) * np.log(errs / errs.min()))
        return a @ (share @ np.array(coefs) / share.sum())
    return fit


def _held_out(lab: np.ndarray, most: int = 200) -> Iterator[tuple[int, np.ndarray]]:
    """Each labelled row held out in turn (at most ``most`` of them, evenly spaced), with the labelled rows
    left."""
    rows = np.flatnonzero(lab)
    for i in rows[np.unique(np.linspace(0, len(rows) - 1, min(len(rows), most)).round().astype(int))]:
        keep = lab.copy()
        keep[i] = False
        yield i, keep


def _loo_rmse(fit: Fit, y: np.ndarray, lab: np.ndarray) -> float:
    """Leave-one-out RMSE of ``fit`` over the labelled rows (at most 200 of them, evenly spaced)."""
    errs = [fit(keep, y)[i] - y[i] for i, keep in _held_out(lab)]
    err = float(np.sqrt(np.mean(np.square(errs))))
    return err if np.isfinite(err) else np.inf


def _starts(by_map: dict[str, list[tuple[str, Fit]]], places: list[int],
            score: Callable[[Fit, int], float]) -> list[list[Fit]]:
    """The first placings the field model's refit starts from, each a fit per place target (``places``, target
    indices; ``score(fit, k)``: the fit's leave-one-out RMSE on target k): on every map whose best fits leave at
    most ``START_SPREAD`` times the leave-one-out error of the best map's (over the coordinates), the fits of least
    error per coordinate, then the next least (``STARTS_PER_MAP``)."""
    ranked = {}
    for name, group in by_map.items():
        errs = np.array([[score(fit, k) for _, fit in group] for k in places])
        ranked[name] = (float(np.sqrt(np.sum(errs.min(axis=1) ** 2))), np.argsort(errs, axis=1, kind="stable"))
    best = min(err for err, _ in ranked.values())
    return [[by_map[name][order[k, rank]][1] for k in range(len(places))]
            for name, (err, order) in ranked.items() if err <= START_SPREAD * best
            for rank in range(min(STARTS_PER_MAP, order.shape[1]))]


def _refit(x: np.ndarray, y: np.ndarray, lab: np.ndarray, starts: list[list[Fit]], *,
           settled: bool = False, bar: Any = None) -> np.ndarray:
    """The places (passes, N, P) of every row after each pass of the field model's refit: from each start, the
    rows ``lab`` does not hold placed by its fits and refitted, the labelled rows at their labels ``y``; the mean
    over the starts. ``settled``: the places (N, P) after every pass and :func:`settle` (each start shaken by
    its own seed), the mean over the starts. ``bar``: a progress display, one step per start."""
    placed = []
    for seed, fits in enumerate(starts):
        first = np.stack([fit(lab, y[:, k]) for k, fit in enumerate(fits)], axis=1)
        first[lab] = y[lab]
        by_pass = places_by_pass(x, first, lab)
        placed.append(settle(x, by_pass[-1], lab, seed=seed) if settled else by_pass)
        if bar is not None:
            bar.update()
    return np.mean(placed, axis=0)


def _refined_loo(x: np.ndarray, y: np.ndarray, lab: np.ndarray, starts: list[list[Fit]], *,
                 bar: Any = None) -> np.ndarray:
    """After each pass (passes, P): per place coordinate, the leave-one-out RMSE over the labelled rows (at most
    ``REFINED_LOO``, evenly spaced) of the refit from ``starts`` (:func:`_refit`): with each held-out press, every
    press the others do not label is placed and refitted, as the labeller does without it. ``bar``: a progress
    display, one step per held-out press and start."""
    return np.sqrt(np.mean(np.square(_refined_errors(x, y, lab, starts, bar=bar)), axis=0))


def _blend(a: np.ndarray, b: np.ndarray, share: float) -> np.ndarray:
    """``a`` and ``b`` blended, ``share`` of ``b``: either alone at a share of 0 or 1 (an infinite error of the
    other counts for nothing), else infinite wherever either is."""
    if share <= 0.0:
        return a
    if share >= 1.0:
        return b
    out = (1.0 - share) * a + share * b
    return np.where(np.isfinite(out), out, np.inf)


def _refined_errors(x: np.ndarray, y: np.ndarray, lab: np.ndarray, starts: list[list[Fit]], *,
                    bar: Any = None) -> np.ndarray:
    """The errors (held, passes, P) behind :func:`_refined_loo`: each held-out press's refitted place after each
    pass less its label; a refit that fails to a non-finite place counts as infinitely wrong."""
    errs = np.array([_refit(x, y, keep, starts, bar=bar)[:, i] - y[i] for i, keep in _held_out(lab, REFINED_LOO)])
    return np.where(np.isfinite(errs), errs, np.inf)
