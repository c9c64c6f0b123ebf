"""The maximum-likelihood fit of the simulator to a reading: its box, its scoring, and that it finds a press."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.angle_fit import FITTED, _bound_shares, axial_error_deg, fit_box, fit_press, markdown, summarise


def test_the_box_is_the_protocols_ranges_and_the_force_spans_the_modulus() -> None:
    config = {"poses": {"offset_mm": 4.0, "tilt_deg": 5.0, "force_n": [2.0, 15.0]}, "randomise_spread": 1.0}
    lo, hi, e_nom = fit_box(config)
    assert lo.shape == hi.shape == (len(FITTED),) and e_nom == 200.0
    assert (lo[1:3] == -4.0).all() and (hi[1:3] == 4.0).all() and (lo[4:6] == -5.0).all() and (hi[4:6] == 5.0).all()
    # a 2 N press on the stiffest skin (300 kPa) reads as 2 * 200 / 300 N on the nominal one; 15 N on 120 kPa as 25 N
    assert math.exp(lo[3]) == pytest.approx(2.0 * 200 / 300) and math.exp(hi[3]) == pytest.approx(15.0 * 200 / 120)
    assert (lo[6], hi[6]) == pytest.approx((30.0, 55.0)) and (lo[7], hi[7]) == pytest.approx((0.8, 2.0))
    # the nominal sensor (no randomisation): its remanence and gap are pinned, the force range is the drawn one
    lo0, hi0, _ = fit_box({"poses": {"force_n": [10.0, 11.0]}})
    assert math.exp(lo0[3]) == pytest.approx(10.0) and math.exp(hi0[3]) == pytest.approx(11.0)
    assert hi0[6] - lo0[6] == pytest.approx(0.25) and lo0[6] == pytest.approx(50.0)


def test_axial_errors_wrap_at_90_degrees() -> None:
    assert axial_error_deg(89.0, -89.0) == pytest.approx(2.0)
    assert axial_error_deg(10.0, 190.0) == pytest.approx(0.0)
    assert axial_error_deg(0.0, 90.0) == pytest.approx(90.0)
    assert axial_error_deg(-3.0, 3.0) == pytest.approx(6.0)


def _row(index: int, label: str, force: float, fit: float, head: float, short: bool = False) -> dict:
    return {"index": index, "label": label, "force_n": force, "fit_error_deg": fit, "head_error_deg": head,
            "short": short}


def test_the_summary_counts_each_estimator_and_the_bound_covers_the_same_presses() -> None:
    rows = [_row(0, "flat_bar", 3.0, 2.0, 7.0), _row(1, "flat_bar", 9.0, 1.0, 1.0),
            _row(2, "cylinder", 4.0, 30.0, 3.0, short=True), _row(3, "cylinder", 12.0, 0.5, 0.2)]
    s = summarise(rows)
    assert s["all"] == {"presses": 4, "fit_within_5": 0.75, "head_within_5": 0.75, "fit_median_deg": 1.5,
                        "head_median_deg": 2.0, "fit_only": 1, "head_only": 1, "short": 1, "short_and_missed": 1}
    assert s["2-5 N"]["presses"] == 2 and s["2-5 N"]["fit_within_5"] == 0.5 and "5-8 N" not in s
    assert s["flat_bar"]["head_within_5"] == 0.5
    # the bound over the same presses: a sigma of 0 is always within, a huge one almost never
    bound = _bound_shares(rows, {0: 0.0, 1: 1e6, 2: 0.0, 3: 1e6})
    assert bound["2-5 N"] == pytest.approx(1.0) and bound["all"] == pytest.approx(0.5, abs=1e-5)
    assert bound["flat_bar"] == pytest.approx(0.5, abs=1e-5)
    with pytest.raises(SystemExit, match="no press 3"):
        _bound_shares(rows, {0: 1.0, 1: 1.0, 2: 1.0})
    text = markdown({"presses": 4, "source": "d.npz test split", "seconds": 1.0, "workers": 1, "summary": s,
                     "bound": bound})
    assert "| 2-5 N | 2 | 50.0% | 50.0% | 100.0% | 1 / 1 |" in text


@pytest.mark.slow
def test_the_fit_finds_a_noise_free_press_from_a_head_twenty_degrees_off() -> None:
    from tactile_manip.sim.objects import IndenterPose
    from tactile_manip.sim.pair import SensorPair
    from tactile_manip.boards import load_board
    from tactile_manip.sim.params import for_board, with_values
    from tactile_manip.sim.shapes import make_indenter

    config = {"poses": {"offset_mm": 4.0, "tilt_deg": 5.0, "force_n": [2.0, 15.0]}, "randomise_spread": 1.0}
    lo, hi, e_nom = fit_box(config)
    sensor = {"magnet.remanence_t": 0.045, "magnet.chip_gap_mm": 1.3, "layer.skin_modulus_kpa": e_nom}
    pose, force = IndenterPose(1.5, -1.0, math.radians(35.0), math.radians(2.0), 0.0), 6.0
    reading = SensorPair(with_values(for_board(load_board("supermag-4x4")), sensor), seed=0).expected_reading_ut(
        make_indenter("hex_bar", size_mm=4.0), pose, force)
    job = {"index": 7, "label": "hex_bar_4mm", "kind": "hex_bar", "kwargs": {"size_mm": 4.0}, "sensor_seed": 0,
           "params": sensor, "force_n": force, "saturated": np.zeros((4, 4, 3), bool).tolist(),
           "reading": reading.tolist(), "head_deg": 55.0, "lo": lo.tolist(), "hi": hi.tolist(), "e_nom": e_nom,
           "truth": [35.0, 1.5, -1.0, math.log(force), 2.0, 0.0, 45.0, 1.3], "truth_start": True}
    row = fit_press(job)
    assert row["head_error_deg"] == pytest.approx(20.0)
    assert row["fit_error_deg"] < 0.5 and not row["short"]
    assert row["ml_error_deg"] < 0.5  # started at the truth of a noise-free reading, the fit stays there
    assert row["fitted"]["x_mm"] == pytest.approx(1.5, abs=0.3)
    assert row["fitted"]["y_mm"] == pytest.approx(-1.0, abs=0.3)


def test_maximum_likelihood_gets_its_own_column_only_when_every_press_has_it() -> None:
    rows = [_row(0, "flat_bar", 3.0, 9.0, 7.0) | {"ml_error_deg": 1.0},
            _row(1, "flat_bar", 4.0, 1.0, 1.0) | {"ml_error_deg": 1.0}]
    s = summarise(rows)
    assert s["all"]["ml_within_5"] == 1.0 and s["all"]["fit_within_5"] == 0.5
    text = markdown({"presses": 2, "source": "d.npz", "seconds": 1.0, "workers": 1, "summary": s})
    assert "| presses | n | fit | ML | head |" in text and "| all | 2 | 50.0% | 100.0% | 50.0% |" in text
    partial = summarise([rows[0], _row(1, "flat_bar", 4.0, 1.0, 1.0)])
    assert "ml_within_5" not in partial["all"]
    assert "ML" not in markdown({"presses": 2, "source": "d.npz", "seconds": 1.0, "workers": 1, "summary": partial})
