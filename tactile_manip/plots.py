"""Figures of tactile data: the (rows, cols, 3) magnetic field and depth images (matplotlib, Agg backend).

matplotlib is imported inside the functions, so importing this module is free.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

PAD_HALF_MM = 10.0
AXES = ("x", "y", "z")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


@dataclass(frozen=True, eq=False)
class FieldArtists:
    """What :func:`plot_field` drew, for updating in place (``view``): heat map, arrows, arrow key, colour bar."""

    image: Any
    arrows: Any
    key: Any
    colorbar: Any
    pitch_mm: float


def plot_field(ax, field_ut: np.ndarray, *, pitch_mm: float = 5.0, title: str = "") -> FieldArtists:
    """Draw a (rows, cols, 3) reading on ``ax``: z as a heat map, (x, y) as arrows at the cell centres, with an
    arrow of known length (the key, below the pad) and a labelled colour bar."""
    f = np.asarray(field_ut, dtype=np.float64)
    rows, cols = f.shape[:2]
    half_x, half_y = cols * pitch_mm / 2, rows * pitch_mm / 2
    im = ax.imshow(f[..., 2], cmap="RdBu_r", extent=(-half_x, half_x, -half_y, half_y))
    x, y = np.meshgrid((np.arange(cols) - (cols - 1) / 2) * pitch_mm, ((rows - 1) / 2 - np.arange(rows)) * pitch_mm)
    arrows = ax.quiver(x, y, f[..., 0], f[..., 1], angles="xy", scale_units="xy", scale=1.0, color="k",
                       width=0.012)
    # the key sits in a strip below the pad, inside the axes, so every layout keeps room for it
    ax.set_ylim(-half_y - 0.6 * pitch_mm, half_y)
    key = ax.quiverkey(arrows, X=-half_x + 0.2 * pitch_mm, Y=-half_y - 0.3 * pitch_mm, U=1.0, label="",
                       labelpos="E", coordinates="data", fontproperties={"size": 9})
    ax.set_title(title or "field: z (colour), x-y (arrows)")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    artists = FieldArtists(im, arrows, key, _colorbar(ax, im, "B_z [uT]"), pitch_mm)
    set_field_ranges(artists, z_range_ut=float(np.abs(f[..., 2]).max()),
                     xy_range_ut=float(np.hypot(f[..., 0], f[..., 1]).max()))
    return artists


def set_field_ranges(artists: FieldArtists, *, z_range_ut: float, xy_range_ut: float) -> None:
    """Colour scale +-``z_range_ut`` and arrows scaled so ``xy_range_ut`` spans 0.45 pitch; the key shows the
    largest 1-2-5 value (uT) not above the range, drawn at the same scale."""
    z, xy = max(z_range_ut, 1e-9), max(xy_range_ut, 1e-9)
    artists.image.set_clim(-z, z)
    artists.arrows.scale = xy / (0.45 * artists.pitch_mm)
    step = nice_step(xy)
    artists.key.U = step
    artists.key.text.set_text(f"{step:g} uT (x-y)")


def nice_step(value: float) -> float:
    """The largest of 1, 2, 5 x 10^k that is <= ``value`` (> 0), e.g. 180 -> 100, 260 -> 200."""
    exp = 10.0 ** np.floor(np.log10(value))
    return float(max(m * exp for m in (1.0, 2.0, 5.0) if m * exp <= value * (1 + 1e-12)))


def annotate_cells(ax, image, values: np.ndarray, *, fmt: str = "{:.0f}") -> None:
    """Write each value of a (R, C) heat map in its cell, white on dark cells and black on light ones."""
    rgba = image.cmap(image.norm(values))
    # relative luminance (Rec. 709 weights) of each cell's colour decides the text colour
    luminance = rgba[..., :3] @ np.array([0.2126, 0.7152, 0.0722])
    for (r, c), v in np.ndenumerate(values):
        ax.text(c, r, fmt.format(v), ha="center", va="center", fontsize=7,
                color="white" if luminance[r, c] < 0.5 else "black")


def _colorbar(ax, image, label: str):
    """A colour bar right of ``ax``, labelled on top: a label along the bar's far side would sit next to the
    neighbouring panel's axis label and read as that panel's."""
    bar = ax.figure.colorbar(image, ax=ax, shrink=0.8)
    bar.ax.set_title(label, fontsize=9, loc="left")
    return bar


def plot_depth(ax, depth_mm: np.ndarray, *, pixel_mm: float = 0.1, title: str = "depth",
               vmax_mm: float | None = None) -> None:
    """Draw a depth image (H, W) in mm with the pad extent on the axes."""
    d = np.asarray(depth_mm, dtype=np.float64)
    hx, hy = d.shape[1] * pixel_mm / 2, d.shape[0] * pixel_mm / 2
    im = ax.imshow(d, cmap="viridis", vmin=0.0, vmax=vmax_mm or max(float(d.max()), 1e-3),
                   extent=(-hx, hx, -hy, hy))
    ax.set_title(title)
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    _colorbar(ax, im, "depth [mm]")


MAX_ANNOTATED_CELLS = 64   # heat maps of larger grids (a 41x72 capacitive pad) get no per-cell numbers
MAX_CHANNEL_PANELS = 4     # scalar readings with more channels show their first four


def sample_figure(field_ut: np.ndarray, depth_mm: np.ndarray | None, *, title: str = "",
                  pixel_mm: float | None = 0.1, path: str | Path | None = None, channels: Any = None,
                  image_unit: str = "mm", image_range: tuple[float, float] | None = None):
    """One figure of a sample, saved when ``path``: the image, then for a magnetic reading (R, C, 3) the field
    as arrows and one heat map per axis, for any other reading one heat map per channel.

    ``channels`` is the dataset's :class:`~tactile_manip.data.ChannelSpec` (None: a magnetic field in uT);
    ``image_unit`` / ``image_range`` label and scale the image (None: its own maximum, from 0).
    """
    plt = _pyplot()
    f = np.asarray(field_ut, dtype=np.float64)
    if f.ndim == 2:
        f = f[..., None]
    magnetic = channels is None or (channels.kind == "magnetic_vector" and f.shape[-1] == 3)
    names = list(AXES) if channels is None else list(channels.names)
    unit = "uT" if channels is None else channels.unit
    shown = list(range(3)) if magnetic else list(range(min(f.shape[-1], MAX_CHANNEL_PANELS)))
    panels = 1 + int(magnetic) + len(shown)
    fig, axes = plt.subplots(1, panels, figsize=(4.4 * panels, 4.2), constrained_layout=True, squeeze=False)
    axes = axes[0]
    if depth_mm is not None:
        _plot_image(axes[0], depth_mm, pixel_mm=pixel_mm, unit=image_unit, value_range=image_range)
    else:
        axes[0].set_axis_off()
    if magnetic:
        plot_field(axes[1], f)
    for ax, i in zip(axes[1 + int(magnetic):], shown):
        _channel_map(ax, f[..., i], label=(f"B_{names[i]}" if magnetic else names[i]), unit=unit,
                     what="chip" if magnetic else "taxel", symmetric=magnetic)
    if title:
        fig.suptitle(title)
    if path is not None:
        path = figure_path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=90)
        plt.close(fig)
    return fig


def _plot_image(ax, image: np.ndarray, *, pixel_mm: float | None, unit: str,
                value_range: tuple[float, float] | None) -> None:
    """The sample's image: depth with the pad extent in mm, any other unit in pixels when the size is unknown."""
    if unit == "mm" and pixel_mm:
        plot_depth(ax, image, pixel_mm=pixel_mm, title="VBTS depth", vmax_mm=value_range[1] if value_range else None)
        return
    img = np.asarray(image, dtype=np.float64)
    lo, hi = value_range if value_range else (0.0, max(float(img.max()), 1e-9))
    if pixel_mm:
        hx, hy = img.shape[1] * pixel_mm / 2, img.shape[0] * pixel_mm / 2
        im = ax.imshow(img, cmap="viridis", vmin=lo, vmax=hi, extent=(-hx, hx, -hy, hy))
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("y [mm]")
    else:
        im = ax.imshow(img, cmap="viridis", vmin=lo, vmax=hi)
        ax.set_xlabel("column [px]")
        ax.set_ylabel("row [px]")
    ax.set_title("image")
    _colorbar(ax, im, unit)


def _channel_map(ax, values: np.ndarray, *, label: str, unit: str, what: str, symmetric: bool) -> None:
    """One channel of a reading (R, C) as a heat map, with its numbers on small grids: symmetric about 0 for a
    baseline-subtracted field, over the values' own range for other channels (a 100 pF pad, raw counts)."""
    if symmetric:
        lim = max(float(np.abs(values).max()), 1e-9)
        im = ax.imshow(values, cmap="RdBu_r", vmin=-lim, vmax=lim)
    else:
        lo, hi = float(values.min()), float(values.max())
        im = ax.imshow(values, cmap="magma", vmin=lo, vmax=max(hi, lo + 1e-9))
    if values.size <= MAX_ANNOTATED_CELLS:
        annotate_cells(ax, im, values)
        ax.set_xticks(range(values.shape[1]))
        ax.set_yticks(range(values.shape[0]))
    ax.set_title(f"{label} per {what} (row 0 = +y)")
    ax.set_xlabel("column")
    ax.set_ylabel("row")
    _colorbar(ax, im, f"{label} [{unit}]")


def figure_path(path: str | Path) -> Path:
    """The file matplotlib's ``savefig(path)`` writes: ``path``, with ``.png`` appended when it has no suffix."""
    path = Path(path)
    return path if path.suffix else path.with_name(path.name + ".png")
