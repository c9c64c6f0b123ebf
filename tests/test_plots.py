"""Figures read as a person reads them: colour bars labelled beside their own panel, numbers readable on
dark cells, an arrow of known length on field plots. Asserted on the figure objects, not on pixels."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.quiver import QuiverKey

from tactile_manip.plots import nice_step, plot_field, sample_figure


@pytest.fixture(scope="module")
def field() -> np.ndarray:
    f = np.random.default_rng(0).normal(0.0, 40.0, (4, 4, 3))
    f[1, 1] = (150.0, -200.0, 300.0)   # a strong chip: dark cells at the colour scale's ends
    f[2, 2] = (0.0, 0.0, 0.0)          # a light cell in the middle of the diverging scale
    return f


@pytest.fixture(scope="module")
def figure(field):
    depth = np.zeros((200, 200), np.float32)
    depth[80:120, 60:140] = 1.2
    fig = sample_figure(field, depth, title="test")
    fig.canvas.draw()
    return fig


def _panels_and_bars(fig):
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    return [ax for ax in fig.axes if ax not in bars], bars


def test_every_panel_has_its_own_labelled_colour_bar_between_it_and_the_next(figure) -> None:
    panels, bars = _panels_and_bars(figure)
    assert len(panels) == len(bars) == 5
    labels = [bar.get_title(loc="left") for bar in bars]
    assert labels == ["depth [mm]", "B_z [uT]", "B_x [uT]", "B_y [uT]", "B_z [uT]"]
    renderer = figure.canvas.get_renderer()
    for i, (panel, bar) in enumerate(zip(panels, bars)):
        assert panel.get_position().x1 <= bar.get_position().x0  # right of its own panel ...
        if i + 1 < len(panels):  # ... and bar, ticks and label end before the next panel's axis label starts
            next_label = panels[i + 1].yaxis.label.get_window_extent(renderer)
            assert bar.get_tightbbox(renderer).x1 < next_label.x0


def test_numbers_on_dark_cells_are_white_and_on_light_cells_black(figure, field) -> None:
    panels, _ = _panels_and_bars(figure)
    for axis, ax in enumerate(panels[2:]):
        texts = {(round(t.get_position()[1]), round(t.get_position()[0])): t for t in ax.texts}
        assert len(texts) == 16
        assert texts[(1, 1)].get_text() == f"{field[1, 1, axis]:.0f}"
        assert texts[(1, 1)].get_color() == "white"   # the strongest chip: the scale's darkest colour
        assert texts[(2, 2)].get_color() == "black"   # zero: the scale's white middle


def test_field_plots_carry_an_arrow_key_in_microtesla(figure) -> None:
    panels, _ = _panels_and_bars(figure)
    keys = [a for a in panels[1].artists if isinstance(a, QuiverKey)]
    assert len(keys) == 1
    xy_max = float(np.hypot(150.0, -200.0))  # 250 uT: the key shows 200 uT at the arrows' own scale
    assert keys[0].U == 200.0 and keys[0].text.get_text() == "200 uT (x-y)"
    assert keys[0].Q is next(c for c in panels[1].collections if c is keys[0].Q)
    assert keys[0].Q.scale == pytest.approx(xy_max / (0.45 * 5.0))


def test_plot_field_returns_what_a_live_view_updates() -> None:
    import matplotlib.pyplot as plt

    from tactile_manip.plots import set_field_ranges

    fig, ax = plt.subplots()
    artists = plot_field(ax, np.zeros((4, 4, 3)))
    set_field_ranges(artists, z_range_ut=80.0, xy_range_ut=37.0)
    assert artists.image.get_clim() == (-80.0, 80.0)
    assert artists.key.U == 20.0 and artists.key.text.get_text() == "20 uT (x-y)"
    plt.close(fig)


@pytest.mark.parametrize("value, step", [(1.0, 1.0), (1.9, 1.0), (2.0, 2.0), (4.99, 2.0), (5.0, 5.0),
                                         (250.0, 200.0), (0.03, 0.02), (9999.0, 5000.0)])
def test_nice_step(value, step) -> None:
    assert nice_step(value) == pytest.approx(step)


def test_a_scalar_reading_of_any_grid_gets_one_heat_map_per_channel():
    from tactile_manip.data import ChannelSpec
    from tactile_manip.plots import sample_figure

    rng = np.random.default_rng(0)
    cap = ChannelSpec(names=("c0",), kind="scalar", unit="pF")
    fig = sample_figure(rng.normal(0, 1, (41, 72, 1)), rng.uniform(0, 1, (82, 144)), channels=cap,
                        image_unit="fraction", pixel_mm=None, image_range=(0.0, 1.0))
    panels = {ax.get_title(): ax for ax in fig.axes}
    assert set(panels) >= {"image", "c0 per taxel (row 0 = +y)"}
    assert panels["image"].images[0].get_clim() == (0.0, 1.0)
    assert not panels["c0 per taxel (row 0 = +y)"].texts  # 2952 cells: no numbers
    xela = ChannelSpec(names=("x", "y", "z"), kind="scalar", unit="counts")
    fig = sample_figure(rng.normal(0, 1, (4, 4, 3)), rng.uniform(0, 255, (40, 40)), channels=xela,
                        image_unit="grey", pixel_mm=None, image_range=(0.0, 255.0))
    titles = [ax.get_title() for ax in fig.axes]
    from matplotlib.quiver import Quiver

    arrows = [c for ax in fig.axes for c in ax.collections if isinstance(c, Quiver)]
    assert "x per taxel (row 0 = +y)" in titles and not arrows  # scalar channels: no field arrows
