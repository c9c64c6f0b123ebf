"""The limits of the twin's protocol: how much of a probe log's reading variance any smooth map of the probe pose
explains, and how well such a map, inverted, places presses; the pieces :mod:`benchmarks.twin_protocol` uses.

Every map here is fitted on the first 80 % of a run's rows (the training rows of ``tactile-manip import``'s
chronological split) with its hyper-parameters chosen by cross-validation inside them (contiguous blocks in time,
so a fold never validates on rows next to the ones that fitted it), and scored on the last 20 %. They are not
physics: they set what a physical twin could reach on the same split, no more.

Explained variance, here and in the protocol: per channel ``1 - sum((measured - predicted)^2) / sum((measured -
mean)^2)`` over the scored rows (the mean of those rows: a bias counts against the prediction), and overall the
same with both sums taken over every channel (so a channel weighs by its variance).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

FOLDS = 5                                   # contiguous blocks of the fitting rows, in time
KNN_K = (1, 2, 3, 5, 8, 13)                 # neighbours tried
Z_SCALE = (1.0, 3.0, 10.0, 30.0)            # a millimetre of depth counts this many in-plane millimetres
TIME_SCALE = (0.0, 3.0, 10.0, 30.0)         # the run's elapsed share counts this many millimetres (time maps)
RBF_SMOOTHING = (1e-3, 1e-1, 10.0, 1e3)     # thin-plate smoothing tried
RBF_NEIGHBOURS = 48                         # a local thin-plate fit from this many nearest fitting rows

Predictor = Callable[[np.ndarray], np.ndarray]


def explained_variance(predicted: np.ndarray, measured: np.ndarray) -> tuple[np.ndarray, float]:
    """Per channel (C,) and overall explained variance of ``predicted`` against ``measured`` (N, C)."""
    p = np.asarray(predicted, np.float64)
    m = np.asarray(measured, np.float64)
    sse = ((m - p) ** 2).sum(axis=0)
    sst = ((m - m.mean(axis=0)) ** 2).sum(axis=0)
    return 1.0 - sse / np.maximum(sst, 1e-300), float(1.0 - sse.sum() / max(sst.sum(), 1e-300))


def _scaled(pose: np.ndarray, params: dict[str, float]) -> np.ndarray:
    """Pose columns (x, y, z[, time share]) scaled for a distance (z by ``z``, time by ``t``), the columns that
    ``params["varies"]`` leaves out (a run at one place has no x and y to speak of) dropped."""
    scale = np.array([1.0, 1.0, params["z"], params.get("t", 0.0)])[:pose.shape[1]]
    return (pose.astype(np.float64) * scale)[:, params["varies"]]


def knn_map(pose: np.ndarray, y: np.ndarray, params: dict[str, float]) -> Predictor:
    from sklearn.neighbors import KNeighborsRegressor

    model = KNeighborsRegressor(int(params["k"]), weights="distance").fit(_scaled(pose, params), y)
    return lambda q: model.predict(_scaled(q, params))


def rbf_map(pose: np.ndarray, y: np.ndarray, params: dict[str, float]) -> Predictor:
    from scipy.interpolate import RBFInterpolator

    x = _scaled(pose, params)
    # repeated poses (a grid visited five times) are merged into their mean reading: the interpolant needs
    # distinct points, and the smoothing does the averaging the repeats would
    keys, inverse = np.unique(np.round(x, 6), axis=0, return_inverse=True)
    mean = np.zeros((len(keys), y.shape[1]))
    np.add.at(mean, inverse.ravel(), y)
    counts = np.bincount(inverse.ravel(), minlength=len(keys))[:, None]
    model = RBFInterpolator(keys, mean / counts, kernel="thin_plate_spline", smoothing=params["s"],
                            neighbors=min(RBF_NEIGHBOURS, len(keys)), degree=1)
    return lambda q: model(_scaled(q, params))


MAPS: dict[str, tuple[Callable[..., Predictor], dict[str, tuple[float, ...]]]] = {
    "kNN": (knn_map, {"k": KNN_K, "z": Z_SCALE}),
    "thin-plate RBF": (rbf_map, {"s": RBF_SMOOTHING, "z": Z_SCALE}),
}


@dataclass(frozen=True)
class MapFit:
    """A smooth map of the pose, its hyper-parameters, their cross-validated explained variance and the map
    refitted on every fitting row."""

    name: str
    params: dict[str, Any]
    cv_ev: float
    predict: Predictor


def choose_map(name: str, pose: np.ndarray, y: np.ndarray, *, with_time: bool = False) -> MapFit:
    """The hyper-parameters of map ``name`` (:data:`MAPS`) of the least cross-validated residual over contiguous
    blocks of the fitting rows ``pose`` (N, 3 or 4), ``y`` (N, C) in time order; the map refitted on all of
    them."""
    build, grid = MAPS[name]
    grid = {**grid, "t": TIME_SCALE if with_time else (0.0,)}
    varies = np.ptp(pose, axis=0) > 1e-3  # a pose column that does not move is no coordinate
    blocks = np.array_split(np.arange(len(pose)), FOLDS)
    best: tuple[float, dict[str, float]] | None = None
    for values in itertools.product(*grid.values()):
        params = {**dict(zip(grid, values)), "varies": varies}
        if with_time and params["t"] == 0.0:
            continue
        sse = sst = 0.0
        try:
            for block in blocks:
                keep = np.setdiff1d(np.arange(len(pose)), block)
                pred = build(pose[keep], y[keep], params)(pose[block])
                sse += float(((y[block] - pred) ** 2).sum())
                sst += float(((y[block] - y[block].mean(axis=0)) ** 2).sum())
        except np.linalg.LinAlgError:  # a local fit on collinear neighbours (a ramp in depth and time): no map
            continue
        ev = 1.0 - sse / sst
        if best is None or ev > best[0]:
            best = (ev, params)
    assert best is not None
    return MapFit(name=name, params=best[1], cv_ev=best[0], predict=build(pose, y, best[1]))


def _public(params: dict[str, Any]) -> dict[str, float]:
    return {k: float(v) for k, v in params.items() if k != "varies"}


def forward_limit(pose: np.ndarray, y: np.ndarray, train: np.ndarray, test: np.ndarray, *,
                  with_time: bool = False) -> dict[str, Any]:
    """Each smooth map of the pose (N, 3 or 4) chosen and fitted on the rows ``train``, scored on ``test``: its
    hyper-parameters, cross-validated and test explained variance (overall and per channel); ``best`` names the
    map of the highest cross-validated figure (chosen without the test rows)."""
    out: dict[str, Any] = {"maps": {}}
    for name in MAPS:
        fit = choose_map(name, pose[train], y[train], with_time=with_time)
        per_channel, overall = explained_variance(fit.predict(pose[test]), y[test])
        out["maps"][name] = {"params": _public(fit.params), "cv_ev": fit.cv_ev, "test_ev": overall,
                             "test_ev_per_channel": per_channel.tolist()}
    out["best"] = max(out["maps"], key=lambda n: out["maps"][n]["cv_ev"])
    out["test_ev"] = out["maps"][out["best"]]["test_ev"]
    return out


def pose_grid(pose: np.ndarray, *, step_mm: float = 0.25, depths: int = 24) -> np.ndarray:
    """(G, 3) a dense grid of poses over the box the fitting poses span: ``step_mm`` in-plane, ``depths``
    levels of z."""
    lo, hi = pose[:, :3].min(axis=0), pose[:, :3].max(axis=0)
    axes = [np.arange(lo[i], hi[i] + step_mm / 2, step_mm) for i in range(2)] + [np.linspace(lo[2], hi[2], depths)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def inverted_places(fit: MapFit, grid: np.ndarray, readings: np.ndarray, *, weight: np.ndarray | None = None
                    ) -> np.ndarray:
    """(N, 3) the pose of the grid whose predicted reading lies nearest each of ``readings`` (N, C), channels
    weighed by ``weight`` (C,) (e.g. one over each channel's residual spread)."""
    from scipy.spatial import cKDTree

    w = np.ones(readings.shape[1]) if weight is None else np.asarray(weight, np.float64)
    bank = fit.predict(grid) * w
    _, idx = cKDTree(bank).query(np.asarray(readings, np.float64) * w, k=1)
    return grid[idx]


def map_bank(fit: MapFit, grid: np.ndarray, live: np.ndarray, template: Any, *,
             targets: dict[str, Callable[[np.ndarray], np.ndarray]]) -> Any:
    """A dataset of presses (what ``train --prior`` reads) that a smooth map predicts at the ``grid`` poses (G, 3):
    readings in ``template``'s layout (a dataset of the same board; ``live`` (C,) its varying channels, flat), and
    per target name the function of the grid poses that gives it. A twin as good as the smooth map."""
    from tactile_manip.data import from_arrays

    flat = np.zeros((len(grid), live.size), np.float32)
    flat[:, live] = fit.predict(grid)
    readings = flat.reshape(len(grid), *template.readings.shape[1:])
    prov = {k: template.provenance[k] for k in ("layout", "board") if k in template.provenance}
    return from_arrays(readings, targets={n: f(grid) for n, f in targets.items()}, val_fraction=0.0,
                       test_fraction=0.0, seed=0, provenance={**prov, "source": "benchmarks.twin_limits.map_bank"})
