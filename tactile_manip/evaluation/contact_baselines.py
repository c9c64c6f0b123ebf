"""Baselines for contact targets, fitted on the training split of the same dataset as the model.

Each maps the newest reading, flattened and standardised with the training split's statistics, to the
targets (no context, no variance):

- ``Linear``: least squares with an intercept;
- ``kNN``: the mean of the 5 nearest training readings, weighted by inverse distance;
- ``MLP``: a plain MLP, two hidden layers of 128 ReLU units, Adam on the squared error of standardised
  targets (the size the eFlesh characterisation used).

kNN and MLP use scikit-learn when it is installed (extra ``baselines``); otherwise the numpy versions here
(the same definitions, trained by the same recipe, not bit-identical to scikit-learn).
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass

import numpy as np

KNN_NEIGHBOURS = 5
MLP_HIDDEN = (128, 128)
MLP_EPOCHS = 500


@dataclass
class Standardiser:
    """Mean and spread of training rows (a constant column keeps spread 1)."""

    mean: np.ndarray
    scale: np.ndarray

    @classmethod
    def fit(cls, x: np.ndarray) -> Standardiser:
        spread = x.std(0)
        return cls(x.mean(0), np.where(spread > 1e-9, spread, 1.0))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return (x - self.mean) / self.scale


def flat(readings: np.ndarray) -> np.ndarray:
    """(N, R, C, A) -> (N, R*C*A) float64."""
    return np.asarray(readings, dtype=np.float64).reshape(len(readings), -1)


def have_sklearn() -> bool:
    return importlib.util.find_spec("sklearn") is not None


def fit_predict_baselines(train_x: np.ndarray, train_y: np.ndarray, test_x: np.ndarray, *,
                          seed: int = 0) -> dict[str, np.ndarray]:
    """Predictions (n_test, K) of each baseline, fitted on ``train_x`` (N, R, C, A) and ``train_y`` (N, K)."""
    xs, ys = Standardiser.fit(flat(train_x)), Standardiser.fit(np.asarray(train_y, np.float64))
    a, b, y = xs(flat(train_x)), xs(flat(test_x)), ys(np.asarray(train_y, np.float64))
    design = np.c_[a, np.ones(len(a))]
    coef = np.linalg.lstsq(design, y, rcond=None)[0]
    out = {"Linear": np.c_[b, np.ones(len(b))] @ coef}
    if have_sklearn():
        out["kNN"], out["MLP"] = _sklearn_knn(a, y, b), _sklearn_mlp(a, y, b, seed)
    else:
        out["kNN"], out["MLP"] = knn_predict(a, y, b), NumpyMLP(a.shape[1], y.shape[1], seed).fit(a, y).predict(b)
    return {k: ys.mean + ys.scale * v.reshape(len(b), -1) for k, v in out.items()}


def _sklearn_knn(a: np.ndarray, y: np.ndarray, b: np.ndarray) -> np.ndarray:
    from sklearn.neighbors import KNeighborsRegressor

    return KNeighborsRegressor(n_neighbors=KNN_NEIGHBOURS, weights="distance").fit(a, y).predict(b)


def _sklearn_mlp(a: np.ndarray, y: np.ndarray, b: np.ndarray, seed: int) -> np.ndarray:
    import warnings

    from sklearn.exceptions import ConvergenceWarning
    from sklearn.neural_network import MLPRegressor

    mlp = MLPRegressor(hidden_layer_sizes=MLP_HIDDEN, max_iter=MLP_EPOCHS, random_state=seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        mlp.fit(a, y if y.shape[1] > 1 else y[:, 0])
    return mlp.predict(b)


def knn_predict(a: np.ndarray, y: np.ndarray, b: np.ndarray, k: int = KNN_NEIGHBOURS) -> np.ndarray:
    """Inverse-distance-weighted mean of the ``k`` nearest rows of ``a`` for each row of ``b`` (numpy)."""
    out = np.empty((len(b), y.shape[1]))
    for s in range(0, len(b), 512):
        d = np.sqrt(np.maximum(((b[s:s + 512, None, :] - a[None]) ** 2).sum(-1), 0))  # (n, N)
        near = np.argpartition(d, min(k, len(a) - 1), axis=1)[:, :k]
        dn = np.take_along_axis(d, near, 1)
        exact = dn < 1e-12
        w = np.where(exact.any(1, keepdims=True), exact.astype(float), 1 / np.maximum(dn, 1e-12))
        out[s:s + 512] = (w[..., None] * y[near]).sum(1) / w.sum(1, keepdims=True)
    return out


class NumpyMLP:
    """Two ReLU hidden layers of 128, Adam (lr 1e-3, batch 200), squared error: scikit-learn's recipe."""

    def __init__(self, inputs: int, outputs: int, seed: int = 0) -> None:
        rng = np.random.default_rng(seed)
        sizes = [inputs, *MLP_HIDDEN, outputs]
        self.params = []
        for i, o in zip(sizes[:-1], sizes[1:]):
            bound = np.sqrt(6 / (i + o))
            self.params += [rng.uniform(-bound, bound, (i, o)), np.zeros(o)]
        self.rng = rng

    def _forward(self, x: np.ndarray) -> list[np.ndarray]:
        acts = [x]
        for j in range(0, len(self.params), 2):
            h = acts[-1] @ self.params[j] + self.params[j + 1]
            acts.append(np.maximum(h, 0) if j < len(self.params) - 2 else h)
        return acts

    def fit(self, x: np.ndarray, y: np.ndarray, *, epochs: int = MLP_EPOCHS, batch: int = 200,
            lr: float = 1e-3, alpha: float = 1e-4) -> NumpyMLP:
        m = [np.zeros_like(p) for p in self.params]
        v = [np.zeros_like(p) for p in self.params]
        step = 0
        for _ in range(epochs):
            order = self.rng.permutation(len(x))
            for s in range(0, len(x), batch):
                i = order[s:s + batch]
                acts = self._forward(x[i])
                grad = (acts[-1] - y[i]) / len(i)
                grads = []
                for j in range(len(self.params) - 2, -1, -2):
                    grads = [acts[j // 2].T @ grad + alpha * self.params[j] / len(i), grad.sum(0)] + grads
                    if j:
                        grad = (grad @ self.params[j].T) * (acts[j // 2] > 0)
                step += 1
                for p, g, mm, vv in zip(self.params, grads, m, v):
                    mm *= 0.9
                    mm += 0.1 * g
                    vv *= 0.999
                    vv += 0.001 * g * g
                    p -= lr * (mm / (1 - 0.9 ** step)) / (np.sqrt(vv / (1 - 0.999 ** step)) + 1e-8)
        return self

    def predict(self, x: np.ndarray) -> np.ndarray:
        return self._forward(x)[-1]
