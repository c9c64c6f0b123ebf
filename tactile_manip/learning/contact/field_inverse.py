"""Placing presses by inverting a smooth model of the field, fitted on the presses' first placing.

The map fits of :mod:`~tactile_manip.learning.contact.fewlabel` place each unlabelled press from its map
coordinates. The map carries, besides its broad squeeze, a local scatter: readings a fraction of a millimetre
apart on the pad land a millimetre apart on the map. This module takes that first placing and refits it from the
field itself:

1. A forward model of the reading's direction (its unit vector over all channels): a polynomial of degree
   ``DEGREE`` in the press's place, whose coefficients are polynomials of degree ``NORM_DEGREE`` in the log field
   norm (the pattern shifts as the skin is pressed deeper; left out where the place alone sets the norm, as for
   presses of one depth per place, since a place would then be searched at norms it never had). Least squares
   over every press at its current place, the labelled ones at their labels, weighted so that the labels (exact
   places) weigh as much together as the other presses (scattered places) together. A low-degree polynomial
   cannot follow a scatter from press to press, so the model is that of the field's smooth layout, pinned where
   the labels are.
2. Each unlabelled press moves to the place, on a grid of ``GRID_STEPS`` steps per axis over the places' extent
   (and ``MARGIN`` of it beyond each side), whose modelled direction is nearest its own in the metric of the
   model's residuals (their inverse covariance: channels that scatter count less).

One pass. Repeating it gains nothing and then drifts: the model learns the errors of its own placing. On the
eFlesh spatial run (25 labelled presses, 8 draws) the first placing is 2.01 mm off and the refitted one 1.74
mm (1.82 mm with every press weighted alike); with 100 labels 1.62 and 1.29 mm (4 draws).
"""

from __future__ import annotations

import numpy as np

DEGREE = 4          # of the forward model in the place
NORM_DEGREE = 2     # of its coefficients in the log field norm
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


def _design(z: np.ndarray, level: np.ndarray, norm_degree: int) -> np.ndarray:
    terms = _monomials(z, DEGREE)
    return np.hstack([terms * level[:, None] ** k for k in range(norm_degree + 1)])


def refine_places(readings: np.ndarray, places: np.ndarray, labelled: np.ndarray,
                  rows: np.ndarray | None = None) -> np.ndarray:
    """New places (N, P) for ``rows`` (default: every row not ``labelled``) of ``readings`` (N, D), given every
    row's current ``places`` (N, P), P = 1 or 2; the other rows keep theirs. ``readings`` must be finite and
    not all zero. Returns ``places`` unchanged (a copy) where the readings are too few for the model's terms
    (``MIN_ROWS_PER_TERM`` each) or the places do not spread."""
    x = np.asarray(readings, np.float64).reshape(len(readings), -1)
    z = np.asarray(places, np.float64).reshape(len(readings), -1)
    out = z.copy()
    lab = np.asarray(labelled, bool)
    move = np.flatnonzero(~lab) if rows is None else np.asarray(rows, int)
    if z.shape[1] not in (1, 2):
        raise ValueError(f"places of {z.shape[1]} coordinates: the field model places in 1 or 2")
    centre, spread = z.mean(axis=0), float(z.std())
    terms = (NORM_DEGREE + 1) * _monomials(z[:1], DEGREE).shape[1]
    if not len(move) or len(x) < MIN_ROWS_PER_TERM * terms or spread <= 0:
        return out
    norm = np.maximum(np.linalg.norm(x, axis=1), 1e-12)
    direction = x / norm[:, None]
    level = np.log(norm)
    level = (level - level.mean()) / max(float(level.std()), 1e-12)
    scaled = (z - centre) / spread
    at_places = _monomials(scaled, DEGREE)
    fitted, *_ = np.linalg.lstsq(at_places, level, rcond=None)
    # where the place sets the norm (one depth per place), a place searched at a norm it never had is unseen:
    # the model then follows the direction alone
    explained = 1.0 - float(np.var(level - at_places @ fitted)) / max(float(np.var(level)), 1e-300)
    norm_degree = 0 if explained > LEVEL_EXPLAINED else NORM_DEGREE
    design = _design(scaled, level, norm_degree)
    # the labelled places are exact, the others scattered: together the labels weigh as much as the rest
    weight = np.sqrt(np.where(lab, max(1.0, (~lab).sum() / max(lab.sum(), 1)), 1.0))[:, None]
    coef, *_ = np.linalg.lstsq(design * weight, direction * weight, rcond=None)
    resid = direction - design @ coef
    cov = np.cov(resid.T).reshape(direction.shape[1], -1)
    cov += np.eye(len(cov)) * max(1e-12, 1e-9 * float(np.trace(cov)))
    white = np.linalg.cholesky(np.linalg.inv(cov))  # d @ white: residuals of unit covariance
    lo, hi = z.min(axis=0), z.max(axis=0)
    pad = MARGIN * (hi - lo)
    axes = [np.linspace(a - p, b + p, GRID_STEPS + 1) for a, b, p in zip(lo, hi, pad)]
    grid = np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")], axis=1)
    mono = _monomials((grid - centre) / spread, DEGREE)
    per = mono.shape[1]
    # the modelled (whitened) direction at each grid point, one array per power of the norm level
    models = [mono @ coef[k * per:(k + 1) * per] @ white for k in range(norm_degree + 1)]
    gram = np.zeros((2 * norm_degree + 1, len(grid)))  # |model|^2 as a polynomial of the level
    for k, mk in enumerate(models):
        for j, mj in enumerate(models):
            gram[k + j] += np.einsum("md,md->m", mk, mj)
    seen = direction @ white
    for start in range(0, len(move), BLOCK):
        block = move[start:start + BLOCK]
        powers = level[block][None, :] ** np.arange(2 * norm_degree + 1)[:, None]  # (2 degree + 1, B)
        cost = gram.T @ powers
        for k, mk in enumerate(models):
            cost -= 2.0 * (mk @ seen[block].T) * powers[k]
        out[block] = grid[np.argmin(cost, axis=0)]
    return out
