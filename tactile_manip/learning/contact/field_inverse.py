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
   model's residuals (their inverse covariance: channels that scatter count less).

Two passes (``PASSES``), coarse to fine. The first model, of degree 4 in the place with coefficients quadratic
in the norm, takes out most of the map's scatter; the second, fitted on the places the first left, is of degree
5 and follows the direction alone. Repeating one model gains nothing and then drifts (the model learns the
errors of its own placing); the finer second pass gains. On the eFlesh spatial run, 25 labelled presses, 8
draws: the first placing 2.01 mm off, after the first pass 1.74 mm, after both 1.62 mm (with the second pass
keeping the norm terms 1.64 mm; of degree 6 or 7, 1.61-1.62 mm). With 100 labels 1.62, 1.29 and
1.17 mm; with 10, 2.92, 2.74 and 2.68 mm (4 draws each).
"""

from __future__ import annotations

import numpy as np

PASSES = ((4, 2), (5, 0))  # per pass: the model's degree in the place, and its coefficients' in the log norm
GRID_STEPS = 120    # grid steps per place axis
MARGIN = 0.06       # grid beyond the places' extent, per side, as a share of it
LEVEL_EXPLAINED = 0.9  # share of the log norm's variance the place explains, beyond which the norm is left out
MIN_ROWS_PER_TERM = 4  # fewer rows than this per model term: the places are returned as they are
BLOCK = 256         # readings per block of the grid search


def _monomials(z: np.ndarray, degree: int) -> np.ndarray:
    """Every monomial of the columns of ``z`` (N, 1 or 2) up to total ``degree``, constant first (N, terms)."""
    if z.shape[1] == 1:
        return np.stack([z[:, 0] ** i for i in range(degree + 1)], axis=1)
    return np.stack([z[:, 0] ** i * z[:, 1] ** j for i in range(degree + 1) for j in range(degree + 1 - i)], axis=1)


def _design(z: np.ndarray, level: np.ndarray, degree: int, norm_degree: int) -> np.ndarray:
    terms = _monomials(z, degree)
    return np.hstack([terms * level[:, None] ** k for k in range(norm_degree + 1)])


def refine_places(readings: np.ndarray, places: np.ndarray, labelled: np.ndarray,
                  rows: np.ndarray | None = None) -> np.ndarray:
    """New places (N, P) for ``rows`` (default: every row not ``labelled``) of ``readings`` (N, D), given every
    row's current ``places`` (N, P), P = 1 or 2; the other rows keep theirs. ``readings`` must be finite and
    not all zero. Each of ``PASSES`` fits its model on the places the pass before left and moves ``rows``.
    Returns ``places`` unchanged (a copy) where the readings are too few for a pass's model
    (``MIN_ROWS_PER_TERM`` rows per term) or the places do not spread."""
    x = np.asarray(readings, np.float64).reshape(len(readings), -1)
    z = np.asarray(places, np.float64).reshape(len(readings), -1)
    out = z.copy()
    lab = np.asarray(labelled, bool)
    move = np.flatnonzero(~lab) if rows is None else np.asarray(rows, int)
    if z.shape[1] not in (1, 2):
        raise ValueError(f"places of {z.shape[1]} coordinates: the field model places in 1 or 2")
    terms = max((norm_degree + 1) * _monomials(z[:1], degree).shape[1] for degree, norm_degree in PASSES)
    if not len(move) or len(x) < MIN_ROWS_PER_TERM * terms or float(z.std()) <= 0:
        return out
    norm = np.maximum(np.linalg.norm(x, axis=1), 1e-12)
    direction = x / norm[:, None]
    level = np.log(norm)
    level = (level - level.mean()) / max(float(level.std()), 1e-12)
    # the labelled places are exact, the others scattered: together the labels weigh as much as the rest
    weight = np.sqrt(np.where(lab, max(1.0, (~lab).sum() / max(lab.sum(), 1)), 1.0))[:, None]
    for degree, norm_degree in PASSES:
        out[move] = _one_pass(direction, level, out, weight, move, degree, norm_degree)
    return out


def _one_pass(direction: np.ndarray, level: np.ndarray, z: np.ndarray, weight: np.ndarray, move: np.ndarray,
              degree: int, norm_degree: int) -> np.ndarray:
    """The places (len(move), P) of the rows ``move``, on the model of ``degree`` in the place and
    ``norm_degree`` in the standardised log norm ``level`` fitted at the places ``z`` (N, P)."""
    centre, spread = z.mean(axis=0), float(z.std())
    scaled = (z - centre) / spread
    if norm_degree:
        at_places = _monomials(scaled, degree)
        fitted, *_ = np.linalg.lstsq(at_places, level, rcond=None)
        # where the place sets the norm (one depth per place), a place searched at a norm it never had is
        # unseen: the model then follows the direction alone
        explained = 1.0 - float(np.var(level - at_places @ fitted)) / max(float(np.var(level)), 1e-300)
        norm_degree = 0 if explained > LEVEL_EXPLAINED else norm_degree
    design = _design(scaled, level, degree, norm_degree)
    coef, *_ = np.linalg.lstsq(design * weight, direction * weight, rcond=None)
    resid = direction - design @ coef
    cov = np.cov(resid.T).reshape(direction.shape[1], -1)
    cov += np.eye(len(cov)) * max(1e-12, 1e-9 * float(np.trace(cov)))
    white = np.linalg.cholesky(np.linalg.inv(cov))  # d @ white: residuals of unit covariance
    lo, hi = z.min(axis=0), z.max(axis=0)
    pad = MARGIN * (hi - lo)
    axes = [np.linspace(a - p, b + p, GRID_STEPS + 1) for a, b, p in zip(lo, hi, pad)]
    grid = np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")], axis=1)
    mono = _monomials((grid - centre) / spread, degree)
    per = mono.shape[1]
    # the modelled (whitened) direction at each grid point, one array per power of the norm level
    models = [mono @ coef[k * per:(k + 1) * per] @ white for k in range(norm_degree + 1)]
    gram = np.zeros((2 * norm_degree + 1, len(grid)))  # |model|^2 as a polynomial of the level
    for k, mk in enumerate(models):
        for j, mj in enumerate(models):
            gram[k + j] += np.einsum("md,md->m", mk, mj)
    seen = direction @ white
    placed = np.empty((len(move), z.shape[1]))
    for start in range(0, len(move), BLOCK):
        block = move[start:start + BLOCK]
        powers = level[block][:, None] ** np.arange(2 * norm_degree + 1)[None, :]  # (B, 2 degree + 1)
        # |model - seen|^2 less |seen|^2, per reading (row) and grid point (column)
        cost = powers @ gram
        for k, mk in enumerate(models):
            cost -= (2.0 * powers[:, k:k + 1] * seen[block]) @ mk.T
        placed[start:start + BLOCK] = grid[np.argmin(cost, axis=1)]
    return placed
