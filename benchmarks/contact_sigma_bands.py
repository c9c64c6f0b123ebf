"""Would a force sigma scaled per band of the predicted force cover the errors more evenly than one scale?

    python -m benchmarks.contact_sigma_bands --data contact_probe6.npz --model contact_probe.onnx

An exported contact model already scales each target's sigma so that 68.3 % of its validation errors fall
within one sigma. Here, on top of that, the force sigma gets one more factor per band of the *predicted*
force (edges ``--edges``, 5 and 10 N), fitted on the dataset's validation split the same way (the 68.3 %
quantile of |error| / sigma of the validation presses predicted in that band), and the share of test errors
within 1 and 2 sigma is compared per band of the *true* force (as ``tactile-manip evaluate`` reports it),
before and after. Nothing is fitted on the test split.

Prints markdown and writes docs/results/benchmarks/contact_sigma_bands.json; asserts nothing.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks._common import machine_info, publish
from tactile_manip.data import load_dataset
from tactile_manip.perception.confidence import ONE_SIGMA
from tactile_manip.perception.contact import ContactEstimator

TRUE_BANDS_N = ((0.5, 5.0), (5.0, 10.0), (10.0, 20.0))
MIN_BAND_PRESSES = 20   # a band with fewer validation presses keeps the factor 1


def force_predictions(est: ContactEstimator, readings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Force mean and sigma (N,) N of single-frame ``readings`` (N, R, C, A)."""
    k = list(est.target_names).index("force_n")
    mean, sigma = est.session.run(None, {"field_ut": readings[:, None].astype(np.float32)})
    return mean[:, k], sigma[:, k]


def band_factors(mean: np.ndarray, sigma: np.ndarray, truth: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """One sigma factor per band of the predicted force (len(edges) + 1,), fitted on these presses."""
    band = np.digitize(mean, edges)
    z = np.abs(mean - truth) / sigma
    return np.array([np.quantile(z[band == b], ONE_SIGMA) if (band == b).sum() >= MIN_BAND_PRESSES else 1.0
                     for b in range(len(edges) + 1)])


def coverage(err: np.ndarray, sigma: np.ndarray) -> dict[str, float]:
    return {"within_1": float(np.mean(err <= sigma)), "within_2": float(np.mean(err <= 2 * sigma))}


def markdown(report: dict[str, Any]) -> str:
    lines = [f"# Force sigma per predicted-force band ({report['model']} on {report['data']})", "",
             f"factors per predicted band (edges {report['edges_n']} N): {report['factors']}", "",
             "| true force band N | test presses | RMSE N | within 1 sigma before / after "
             "| within 2 sigma before / after |",
             "|---|---|---|---|---|"]
    for r in report["bands"]:
        b, a = r["before"], r["after"]
        lines.append(f"| {r['band_n'][0]} - {r['band_n'][1]} | {r['n']} | {r['rmse_n']:.3f} | "
                     f"{b['within_1']:.1%} / {a['within_1']:.1%} | {b['within_2']:.1%} / {a['within_2']:.1%} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", required=True, help="a dataset with force_n targets and val and test splits")
    parser.add_argument("--model", required=True, help="an exported single-frame contact model (.onnx)")
    parser.add_argument("--edges", default="5,10", help="edges of the predicted-force bands, N")
    parser.add_argument("--out", default="docs/results/benchmarks/contact_sigma_bands.json")
    args = parser.parse_args(argv)

    data, est = load_dataset(args.data), ContactEstimator(args.model)
    edges = np.array([float(e) for e in args.edges.split(",")])
    val, test = data.indices("val"), data.indices("test")
    force = data.target("force_n")
    mv, sv = force_predictions(est, data.readings[val])
    factors = band_factors(mv, sv, force[val], edges)
    mt, st = force_predictions(est, data.readings[test])
    st_after, err, truth = st * factors[np.digitize(mt, edges)], np.abs(mt - force[test]), force[test]
    bands = []
    for lo, hi in TRUE_BANDS_N:
        sel = (truth >= lo) & (truth < hi)
        bands.append({"band_n": [lo, hi], "n": int(sel.sum()), "rmse_n": float(np.sqrt((err[sel] ** 2).mean())),
                      "before": coverage(err[sel], st[sel]), "after": coverage(err[sel], st_after[sel])})
    report = {"data": Path(args.data).name, "model": Path(args.model).name, "edges_n": edges.tolist(),
              "factors": [round(float(f), 3) for f in factors], "bands": bands,
              "all": {"before": coverage(err, st), "after": coverage(err, st_after)}, "machine": machine_info()}
    publish(report, Path(args.out), markdown)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
