"""The bar shapes the angle head learns from and is tested on: flat bars and the procedural bar family."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_manip.sim.shapes import SHAPES, flat_bar, make_indenter, procedural_bar, procedural_prism

PX = 0.05


def _footprint(height_mm: np.ndarray) -> tuple[float, float]:
    """Extent (mm) of the finite protrusion along local x (columns) and y (rows)."""
    finite = np.isfinite(height_mm)
    return (finite.any(axis=0).sum() - 1) * PX, (finite.any(axis=1).sum() - 1) * PX


@pytest.mark.parametrize("width, thickness, length", [(12.0, 3.0, 40.0), (20.0, 1.5, 30.0), (2.0, 0.5, 10.0)])
def test_a_flat_bar_has_the_asked_footprint_and_a_flat_face(width, thickness, length) -> None:
    h = flat_bar(width_mm=width, thickness_mm=thickness, fillet_mm=0.2, length_mm=length).height_mm
    along, across = _footprint(h)
    assert along == pytest.approx(length, abs=2 * PX)
    assert across == pytest.approx(width, abs=2 * PX)
    assert np.nanmax(h) == pytest.approx(thickness / 2)
    rows = np.isfinite(h).any(axis=1)
    middle = h[np.flatnonzero(rows)[len(np.flatnonzero(rows)) // 2]]
    face = middle[np.isfinite(middle)]
    assert np.mean(face == np.nanmax(h)) > 0.8  # the face is flat but for the filleted ends


def test_the_fillet_rounds_the_edges_down() -> None:
    sharp = flat_bar(width_mm=10.0, thickness_mm=2.0, fillet_mm=0.0).height_mm
    round_ = flat_bar(width_mm=10.0, thickness_mm=2.0, fillet_mm=0.8).height_mm
    assert np.nanmin(sharp) == pytest.approx(1.0)
    assert np.nanmin(round_) < 1.0 - 0.5


@pytest.mark.parametrize("kwargs, match", [
    ({"width_mm": 25.0}, "width_mm"), ({"thickness_mm": 0.1}, "thickness_mm"),
    ({"width_mm": 4.0, "thickness_mm": 1.0, "fillet_mm": 0.8}, "fillet_mm"), ({"length_mm": 5.0}, "length_mm"),
    ({"width_mm": float("nan")}, "width_mm")])
def test_flat_bar_arguments_are_checked(kwargs, match) -> None:
    with pytest.raises(ValueError, match=match):
        flat_bar(**kwargs)


def test_a_procedural_bar_is_the_same_for_a_seed_and_differs_between_seeds() -> None:
    a, b, c = (procedural_bar(s).height_mm for s in (3, 3, 4))
    np.testing.assert_array_equal(a, b)
    assert a.shape != c.shape or not np.array_equal(np.nan_to_num(a), np.nan_to_num(c))


def test_procedural_bars_span_narrow_to_pad_wide_and_lie_along_local_x() -> None:
    widths = []
    for seed in range(40):
        h = procedural_bar(seed, length_mm=30.0).height_mm
        along, across = _footprint(h)
        assert along == pytest.approx(30.0, abs=2 * PX)
        assert across < along
        assert np.nanmax(h) <= 4.0 + 1e-9 and np.nanmin(h) >= 0.0
        widths.append(across)
    assert min(widths) < 5.0 and max(widths) > 15.0


@pytest.mark.parametrize("seed", [-1, 1.5, True])
def test_procedural_bar_seeds_must_be_non_negative_integers(seed) -> None:
    with pytest.raises(ValueError, match="seed"):
        procedural_bar(seed)
    with pytest.raises(ValueError, match="seed"):
        procedural_prism(seed)


def test_procedural_prisms_are_sharp_edged_bars_of_any_length_lying_on_a_face() -> None:
    lengths, widths, flat_tops = [], [], 0
    for seed in range(60):
        h = procedural_prism(seed).height_mm
        along, across = _footprint(h)
        lengths.append(along)
        widths.append(across)
        assert along > across or along >= 12.0 - 2 * PX     # a bar along local x (a wide strip may be short)
        mid = h[:, h.shape[1] // 2]
        top = np.nanmax(mid)
        # the face on the pad is flat: its highest line is a plateau, not a point
        flat_tops += np.sum(np.isclose(mid, top, atol=1e-6)) * PX >= 0.5
        # flat-cut ends: the height across the section is the same all along the bar
        np.testing.assert_allclose(h[:, h.shape[1] // 4], mid, equal_nan=True)
    assert min(lengths) < 20.0 and max(lengths) > 40.0   # some end on the 20 mm pad, some do not
    assert min(widths) < 4.0 and max(widths) > 14.0
    assert flat_tops == 60
    np.testing.assert_array_equal(procedural_prism(5).height_mm, procedural_prism(5).height_mm)


def test_both_are_in_the_registry() -> None:
    assert {"flat_bar", "procedural_bar", "procedural_prism"} <= set(SHAPES)
    assert make_indenter("procedural_prism", seed=7).name == "procedural_prism_7"
    assert make_indenter("procedural_bar", seed=7).name == "procedural_bar_7"
    assert make_indenter("flat_bar", width_mm=8.0).name == "flat_bar"
