"""Placing presses by inverting a smooth model of the field, fitted on the presses' first placing.

The map fits of :mod:`~tactile_manip.learning.contact.fewlabel` place each unlabelled press from its map
coordinates. The map carries, besides its broad squeeze, a local scatter: readings a fraction of a millimetre
apart on the pad land a millimetre apart on the map. This module takes that first placing and refits it from the
field itself:

1. A forward model of the reading's direction (its unit vector over all channels): a polynomial in the press's
   place, whose coefficients are polynomials in the log field norm (the pattern shifts as the skin is pressed
   deeper; left out where the place alone sets the norm, as for presses of one depth per place, since a place
   would then be searched at norms it never had). Least squares over every press at its current place, the
   labelled ones at their labels, weighted so that the labels (exact places) weigh as much together as the
   other presses (scattered places) together. A low-degree polynomial cannot follow a scatter from press to
   press, so the model is that of the field's smooth layout, pinned where the labels are.
2. Each unlabelled press moves to the place, on a grid of ``GRID_STEPS`` steps per axis over the places' extent
   (and ``MARGIN`` of it beyond each side), whose modelled direction is nearest its own in the metric of the
   model's residuals (their inverse covariance: channels that scatter count less). In two coordinates the grid
   is searched coarse to fine: every ``COARSE``-th point per axis, then the whole grid around the ``CANDIDATES``
   best of those. On the eFlesh spatial run it lands every press where the exhaustive search does, to the last
   bit, in half the time.

Six passes (``PASSES``), coarse to fine. The first model, of degree 4 in the place with coefficients quadratic in
the norm, takes out most of the map's scatter; the second, fitted on the places the first left, is of degree 5 and
follows the direction alone; the third adds to it the part of the field that repeats across the pad, as a printed
lattice of cells makes it: the cosine and sine of the place at one period (and their products across the axes), each
times a linear function of the place, the period being the one of ``LATTICE_PERIODS`` (in the places' units: mm for
``x_mm``, ``y_mm``) whose model leaves the least weighted residual, which needs no labels (found once, at the third
pass). The last three keep the repeating terms and follow finer detail of the field: degree 7 and 9 with
coefficients linear in the norm, then degree 11 with quadratic ones. Repeating one model gains nothing and then
drifts (the model learns the errors of its own placing); each finer pass gains, on a field with detail finer than a
polynomial of degree 5 can follow. On the eFlesh spatial run, 25 labelled presses placed first by the map fit of
least leave-one-out error, 16 draws (the passes were chosen on six of them): the first placing 2.13 mm off, after
the passes 1.83, 1.70, 1.64, 1.59, 1.58 and 1.57 mm (after six closer than after three in every draw; 24 further
draws, not used for any choice: 2.14, then 1.87, 1.74, 1.69, 1.65, 1.63 and 1.62 mm, closer in every draw). Fitted
at every press's true place, the finest model places the presses 0.50 mm off, the models of degree 7 and 9 0.55 and
0.52 mm, the second and third 0.81 and 0.71 mm: the finer passes follow the field more closely. The period chosen
there is 8-10 mm in every draw; the field model's residual at every press's true place has its strongest repeating
component at about 7.8 mm. On a smooth field the finer passes learn the placing's errors instead, so
:func:`places_by_pass` returns the places after every pass and the labeller keeps the number of passes with the
least leave-one-out error on its labels. With 100 labels and three passes: 1.62 mm first, 1.17 mm after two, 1.05 mm
after three (4 draws); with 10: 2.92, 2.68 and 2.67 mm.

The passes stop where the places agree with a model fitted on them, and any smooth bend of the places is such an
agreement: the first placing's bend survives them wherever the labels do not reach. :func:`settle` repeats the last
three passes with every moved place shaken after each pass, the shake shrinking to nothing, and keeps the mean of
the places over the second half of its passes. The shaking keeps the places from agreeing exactly with their own
model, so each pass moves them again, and what it moves them towards is what the labels (pinned) and the field say,
not where they started. On the eFlesh spatial run, 25 labelled presses, the labeller's four starts, the places of
the six passes against those settled, 1.44 to 1.17 mm over the three draws the shake was chosen on, and 1.44 to
1.28 mm over nine further draws, closer in eight (the ninth 1.333 to 1.335 mm). With 100 labels, where the passes
leave less bend, it is even: 0.86 to 0.80 and 0.90 to 0.95 mm over two draws.
"""

from __future__ import annotations

import itertools

import numpy as np

# per pass: the model's degree in the place, its coefficients' in the log norm, and whether it adds the repeating
# pattern of the skin's cells
PASSES = ((4, 2, False), (5, 0, False), (5, 0, True), (7, 1, True), (9, 1, True), (11, 2, True))
SETTLE_PASSES = PASSES[3:]  # the passes :func:`settle` repeats, in turn
SETTLE_CYCLES = 8   # times it repeats them
SHAKE_STEPS = 3.0   # how far it shakes each moved place after its first pass, in grid steps per axis; the shake
                    # shrinks in even steps to nothing over its passes
LATTICE_PERIODS = (5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 12.0, 14.0)  # candidate periods of the repeating pattern
LATTICE_DEGREE = 1  # degree in the place of each repeating term's amplitude
GRID_STEPS = 120    # grid steps per place axis
MARGIN = 0.06       # grid beyond the places' extent, per side, as a share of it
LEVEL_EXPLAINED = 0.9  # share of the log norm's variance the place explains, beyond which the norm is left out
MIN_ROWS_PER_TERM = 4  # fewer rows than this per model term: the places are returned as they are
BLOCK = 256         # readings per block of the grid search
COARSE = 4          # in two coordinates the search first scores every COARSE-th grid point per axis,
CANDIDATES = 4      # then every point within COARSE steps of the CANDIDATES best of those


def _monomials(z: np.ndarray, degree: int) -> np.ndarray:
    """Every monomial of the columns of ``z`` (N, 1 or 2) up to total ``degree``, constant first (N, terms)."""
    powers = z[:, :, None] ** np.arange(degree + 1)  # (N, P, degree + 1)
    if z.shape[1] == 1:
        return powers[:, 0]
    return np.hstack([powers[:, 0, i:i + 1] * powers[:, 1, :degree + 1 - i] for i in range(degree + 1)])


def _design(z: np.ndarray, level: np.ndarray, degree: int, norm_degree: int) -> np.ndarray:
    terms = _monomials(z, degree)
    return np.hstack([terms * level[:, None] ** k for k in range(norm_degree + 1)])


def refine_places(readings: np.ndarray, places: np.ndarray, labelled: np.ndarray,
                  rows: np.ndarray | None = None) -> np.ndarray:
    """New places (N, P) for ``rows`` (default: every row not ``labelled``) of ``readings`` (N, D), given every
    row's current ``places`` (N, P), P = 1 or 2: those after the last pass of :func:`places_by_pass`."""
    return places_by_pass(readings, places, labelled, rows)[-1]


def places_by_pass(readings: np.ndarray, places: np.ndarray, labelled: np.ndarray,
                   rows: np.ndarray | None = None, fitted: np.ndarray | None = None) -> np.ndarray:
    """The places (len(``PASSES``), N, P) after each pass of the refit of ``rows`` (default: every row not
    ``labelled``) of ``readings`` (N, D), given every row's current ``places`` (N, P), P = 1 or 2; the other rows
    keep theirs. ``readings`` must be finite and not all zero. Each of ``PASSES`` fits its model on the places the
    pass before left and moves ``rows``. ``fitted`` (N,) bool: the rows each model is fitted on (default: every
    row); the others are only placed on it, as readings a fit must not see (a run's test presses) are. A pass whose
    model has more terms than the fitted rows allow (``MIN_ROWS_PER_TERM`` rows per term) is left out, and with it
    every finer one, as is a pass of the repeating pattern on a pad too small for it: its places are those of the
    pass before, or ``places`` themselves (a copy) where no pass runs or the places do not spread."""
    x = np.asarray(readings, np.float64).reshape(len(readings), -1)
    z = np.asarray(places, np.float64).reshape(len(readings), -1)
    out = z.copy()
    lab = np.asarray(labelled, bool)
    move = np.flatnonzero(~lab) if rows is None else np.asarray(rows, int)
    fit = np.ones(len(x), bool) if fitted is None else np.asarray(fitted, bool)
    if z.shape[1] not in (1, 2):
        raise ValueError(f"places of {z.shape[1]} coordinates: the field model places in 1 or 2")
    if fit.shape != (len(x),):
        raise ValueError(f"a fitted-rows mask of shape {fit.shape} for {len(x)} readings")
    # the passes, coarse to fine, up to the first whose model has more terms than the fitted rows allow
    passes = list(itertools.takewhile(lambda spec: fit.sum() >= MIN_ROWS_PER_TERM * _terms(z.shape[1], *spec),
                                      PASSES))
    if not len(move) or not passes or _frame(z[fit])[1] <= 0:
        return np.repeat(out[None], len(PASSES), axis=0)
    direction, level, weight = _inputs(x, lab, fit)
    period, sought = None, False
    after = []
    for degree, norm_degree, lattice in passes:
        if lattice and not sought:  # the skin's period, found once, on the places the passes before left
            period, sought = _lattice_period(direction[fit], out[fit], weight[fit], degree), True
        if not lattice or period is not None:  # (a pad too small for the pattern to repeat: the pass is left out)
            out = out.copy()
            out[move] = _one_pass(direction, level, out, weight, move, degree, norm_degree,
                                  period if lattice else None, fit=fit)
        after.append(out)
    return np.stack(after + [out] * (len(PASSES) - len(after)))


def settle(readings: np.ndarray, places: np.ndarray, labelled: np.ndarray, rows: np.ndarray | None = None,
           seed: int = 0) -> np.ndarray:
    """New places (N, P) for ``rows`` (default: every row not ``labelled``) of ``readings`` (N, D), given every
    row's ``places`` (N, P) after the last pass of :func:`places_by_pass`: ``SETTLE_CYCLES`` more rounds of its
    finer passes (``SETTLE_PASSES``), each moved place shaken after each pass by a uniform random step of up to
    ``SHAKE_STEPS`` grid steps per axis, the most at the first pass and shrinking evenly to nothing; the places are
    the mean of those the second half of the passes leave (``seed`` seeds the shaking). Places it cannot model (too
    few readings for the finer models, a pad too small for the repeating pattern, places that do not spread) are
    returned as they are (a copy).

    Where the places start without a bend (placed near their true places), settling leaves them where its shaking
    lets them rest, which can be farther than the passes alone: started at every eFlesh press's true place, six
    passes leave 0.96-0.97 mm and settling 1.15-1.17 mm (two draws of 25 labels); on the synthetic lattice of the
    tests, from a scatter without a bend, 0.70 and 0.81 mm. Its gain is where a bend is, as in the labeller's
    first placing from a map."""
    x = np.asarray(readings, np.float64).reshape(len(readings), -1)
    z = np.asarray(places, np.float64).reshape(len(readings), -1).copy()
    lab = np.asarray(labelled, bool)
    move = np.flatnonzero(~lab) if rows is None else np.asarray(rows, int)
    if z.shape[1] not in (1, 2):
        raise ValueError(f"places of {z.shape[1]} coordinates: the field model places in 1 or 2")
    passes = [spec for spec in SETTLE_PASSES if len(x) >= MIN_ROWS_PER_TERM * _terms(z.shape[1], *spec)]
    if not len(move) or len(passes) < len(SETTLE_PASSES) or _frame(z)[1] <= 0:
        return z
    direction, level, weight = _inputs(x, lab)
    period = _lattice_period(direction, z, weight, PASSES[2][0])
    if period is None and any(lattice for *_, lattice in passes):
        return z
    rng = np.random.default_rng(seed)
    schedule = passes * SETTLE_CYCLES
    late = len(schedule) // 2
    mean = np.zeros((len(move), z.shape[1]))
    for i, (degree, norm_degree, lattice) in enumerate(schedule):
        z[move] = _one_pass(direction, level, z, weight, move, degree, norm_degree, period if lattice else None)
        if i >= late:
            mean += z[move] / (len(schedule) - late)
        step = (z.max(axis=0) - z.min(axis=0)) * (1.0 + 2.0 * MARGIN) / GRID_STEPS
        z[move] += rng.uniform(-1.0, 1.0, (len(move), z.shape[1])) * step * SHAKE_STEPS * (1.0 - i / len(schedule))
    z[move] = mean
    return z


def _inputs(x: np.ndarray, lab: np.ndarray, fit: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The models' inputs from readings ``x`` (N, D) and the labelled rows ``lab`` (N,): each reading's direction
    (N, D), its log norm (N,) standardised on the rows ``fit`` (N,) bool (default: every row), and each row's weight
    in the fits (N, 1), so that the labelled places (exact) weigh as much together as the others (scattered)
    together."""
    fit = np.ones(len(x), bool) if fit is None else fit
    norm = np.maximum(np.linalg.norm(x, axis=1), 1e-12)
    level = np.log(norm)
    level = (level - level[fit].mean()) / max(float(level[fit].std()), 1e-12)
    weight = np.sqrt(np.where(lab, max(1.0, (~lab & fit).sum() / max((lab & fit).sum(), 1)), 1.0))[:, None]
    return x / norm[:, None], level, weight


def _frame(z: np.ndarray) -> tuple[np.ndarray, float]:
    """The centre (P,) and spread of places ``z`` (N, P) that the models scale the place by: the mean, and the
    root mean square of each coordinate's deviation from its own mean, so that where the rig's frame puts its
    origin changes nothing (a spread about one mean over both coordinates would grow with the origin's distance,
    and the high powers of the scaled place would fall below the least-squares solver's cut-off)."""
    return z.mean(axis=0), float(np.sqrt(np.mean(z.var(axis=0))))


def _terms(coordinates: int, degree: int, norm_degree: int, lattice: bool) -> int:
    """The number of terms of a pass's model in places of ``coordinates`` (1 or 2)."""
    place = np.zeros((1, coordinates))
    return ((norm_degree + 1) * _monomials(place, degree).shape[1]
            + (_repeating(place, 1.0, place, 1.0).shape[1] if lattice else 0))


def _repeating(z: np.ndarray, period: float, centre: np.ndarray, spread: float) -> np.ndarray:
    """The repeating terms at places ``z`` (N, P): the cosine and sine of each coordinate at ``period`` (and, in
    two coordinates, their four products), each times every monomial of the scaled place up to
    ``LATTICE_DEGREE``."""
    phase = 2.0 * np.pi * z / period
    waves = [np.cos(phase[:, 0]), np.sin(phase[:, 0])]
    if z.shape[1] == 2:
        across = [np.cos(phase[:, 1]), np.sin(phase[:, 1])]
        waves += across + [a * b for a in waves[:2] for b in across]
    amplitude = _monomials((z - centre) / spread, LATTICE_DEGREE)
    return np.hstack([wave[:, None] * amplitude for wave in waves])


def _lattice_period(direction: np.ndarray, z: np.ndarray, weight: np.ndarray, degree: int) -> float | None:
    """The period of ``LATTICE_PERIODS`` whose repeating terms, beside the polynomial of ``degree`` in the place,
    leave the least weighted residual of the direction at the places ``z``; None where no period fits twice
    within the places' extent."""
    centre, spread = _frame(z)
    base = _monomials((z - centre) / spread, degree)
    extent = float((z.max(axis=0) - z.min(axis=0)).min())
    best = None
    for period in LATTICE_PERIODS:
        if 2.0 * period > extent:
            continue
        design = np.hstack([base, _repeating(z, period, centre, spread)]) * weight
        coef, *_ = np.linalg.lstsq(design, direction * weight, rcond=None)
        left = float(np.sum((direction * weight - design @ coef) ** 2))
        if best is None or left < best[0]:
            best = (left, period)
    return None if best is None else best[1]


def _one_pass(direction: np.ndarray, level: np.ndarray, z: np.ndarray, weight: np.ndarray, move: np.ndarray,
              degree: int, norm_degree: int, period: float | None = None, *,
              fit: np.ndarray | None = None) -> np.ndarray:
    """The places (len(move), P) of the rows ``move``, on the model of ``degree`` in the place and
    ``norm_degree`` in the standardised log norm ``level`` fitted at the places ``z`` (N, P) of the rows ``fit``
    (N,) bool (default: every row), plus the repeating terms at ``period`` where one is given."""
    if fit is not None:
        direction_fit, level_fit, z_fit, weight_fit = direction[fit], level[fit], z[fit], weight[fit]
    else:
        direction_fit, level_fit, z_fit, weight_fit = direction, level, z, weight
    centre, spread = _frame(z_fit)
    scaled = (z_fit - centre) / spread
    if norm_degree:
        at_places = _monomials(scaled, degree)
        fitted, *_ = np.linalg.lstsq(at_places, level_fit, rcond=None)
        # where the place sets the norm (one depth per place), a place searched at a norm it never had is
        # unseen: the model then follows the direction alone
        explained = 1.0 - float(np.var(level_fit - at_places @ fitted)) / max(float(np.var(level_fit)), 1e-300)
        norm_degree = 0 if explained > LEVEL_EXPLAINED else norm_degree
    design = _design(scaled, level_fit, degree, norm_degree)
    if period is not None:
        design = np.hstack([design, _repeating(z_fit, period, centre, spread)])
    coef, *_ = np.linalg.lstsq(design * weight_fit, direction_fit * weight_fit, rcond=None)
    resid = direction_fit - design @ coef
    cov = np.cov(resid.T).reshape(direction.shape[1], -1)
    floor = max(1e-12, 1e-9 * float(np.trace(cov)))
    # d @ white: residuals of unit covariance. From the eigenvectors, not a Cholesky factor of the inverse: where
    # the readings span fewer dimensions than their channels, the inverse's rounding can leave it indefinite.
    vals, vecs = np.linalg.eigh(cov)
    white = vecs / np.sqrt(np.maximum(vals, 0.0) + floor)
    lo, hi = z_fit.min(axis=0), z_fit.max(axis=0)
    pad = MARGIN * (hi - lo)
    axes = [np.linspace(a - p, b + p, GRID_STEPS + 1) for a, b, p in zip(lo, hi, pad)]
    grid = np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")], axis=1)
    mono = _monomials((grid - centre) / spread, degree)
    per = mono.shape[1]
    # the modelled (whitened) direction at each grid point, one array per power of the norm level
    models = [mono @ coef[k * per:(k + 1) * per] @ white for k in range(norm_degree + 1)]
    if period is not None:
        models[0] = models[0] + _repeating(grid, period, centre, spread) @ coef[(norm_degree + 1) * per:] @ white
    gram = np.zeros((2 * norm_degree + 1, len(grid)))  # |model|^2 as a polynomial of the level
    for k, mk in enumerate(models):
        for j, mj in enumerate(models):
            gram[k + j] += np.einsum("md,md->m", mk, mj)
    seen = direction @ white
    placed = np.empty((len(move), z.shape[1]))
    side = GRID_STEPS + 1
    coarse_axis = np.unique(np.r_[np.arange(0, side, COARSE), side - 1])
    coarse = (coarse_axis[:, None] * side + coarse_axis[None, :]).ravel() if z.shape[1] == 2 else None
    around = np.arange(-COARSE, COARSE + 1)
    for start in range(0, len(move), BLOCK):
        block = move[start:start + BLOCK]
        powers = level[block][:, None] ** np.arange(2 * norm_degree + 1)[None, :]  # (B, 2 degree + 1)
        if coarse is None:  # one coordinate: every grid point
            cost = _grid_cost(powers, seen[block], models, gram, np.arange(len(grid)))
            placed[start:start + BLOCK] = grid[np.argmin(cost, axis=1)]
            continue
        # two: every COARSE-th point per axis, then every point within COARSE steps of the CANDIDATES best
        cost = _grid_cost(powers, seen[block], models, gram, coarse)
        best = coarse[np.argpartition(cost, min(CANDIDATES, len(coarse)) - 1, axis=1)[:, :CANDIDATES]]
        row, col = np.divmod(best, side)
        rows = np.clip(row[:, :, None, None] + around[:, None], 0, side - 1)
        cols = np.clip(col[:, :, None, None] + around, 0, side - 1)
        points = (rows * side + cols).reshape(len(block), -1)
        cost = _grid_cost(powers, seen[block], models, gram, points)
        placed[start:start + BLOCK] = grid[points[np.arange(len(block)), np.argmin(cost, axis=1)]]
    return placed


def _grid_cost(powers: np.ndarray, seen: np.ndarray, models: list[np.ndarray], gram: np.ndarray,
               points: np.ndarray) -> np.ndarray:
    """|model - seen|^2 less |seen|^2 (B, M) of each of B readings (``seen``, whitened, with their norm level's
    ``powers``) at grid ``points``: M indices shared by every reading, or (B, M), each reading its own."""
    if points.ndim == 1:
        cost = powers @ gram[:, points]
        for k, mk in enumerate(models):
            cost -= (2.0 * powers[:, k:k + 1] * seen) @ mk[points].T
        return cost
    cost = np.einsum("bk,kbm->bm", powers, gram[:, points])
    for k, mk in enumerate(models):
        cost -= np.einsum("bd,bmd->bm", 2.0 * powers[:, k:k + 1] * seen, mk[points])
    return cost
