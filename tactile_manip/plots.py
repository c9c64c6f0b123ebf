"""Figures of tactile data: the 4x4x3 magnetic field and depth images (matplotlib, Agg backend).

matplotlib is imported inside the functions, so importing this module is free.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

PAD_HALF_MM = 10.0
AXES = ("x", "y", "z")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_field(ax, field_ut: np.ndarray, *, pitch_mm: float = 5.0, title: str = "") -> None:
    """Draw a (4, 4, 3) reading on ``ax``: z as a heat map, (x, y) as arrows at the chip positions."""
    f = np.asarray(field_ut, dtype=np.float64)
    half = 2 * pitch_mm
    lim = max(float(np.abs(f[..., 2]).max()), 1e-9)
    im = ax.imshow(f[..., 2], cmap="RdBu_r", vmin=-lim, vmax=lim, extent=(-half, half, -half, half))
    c = (np.arange(4) - 1.5) * pitch_mm
    x, y = np.meshgrid(c, -c)
    scale = max(float(np.hypot(f[..., 0], f[..., 1]).max()), 1e-9) / (0.45 * pitch_mm)
    ax.quiver(x, y, f[..., 0], f[..., 1], angles="xy", scale_units="xy", scale=scale, color="k", width=0.012)
    ax.set_title(title or "field: z (colour), x-y (arrows)")
    ax.set_xlabel("x [mm]")
    ax.set_ylabel("y [mm]")
    ax.figure.colorbar(im, ax=ax, label="B_z [uT]", shrink=0.8)


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
    ax.figure.colorbar(im, ax=ax, label="depth [mm]", shrink=0.8)


def sample_figure(field_ut: np.ndarray, depth_mm: np.ndarray | None, *, title: str = "",
                  pixel_mm: float = 0.1, path: str | Path | None = None):
    """One figure: depth image, the field as arrows, and one heat map per axis. Saved when ``path``."""
    plt = _pyplot()
    f = np.asarray(field_ut, dtype=np.float64)
    fig, axes = plt.subplots(1, 5, figsize=(22, 4.2), constrained_layout=True)
    if depth_mm is not None:
        plot_depth(axes[0], depth_mm, pixel_mm=pixel_mm, title="VBTS depth")
    else:
        axes[0].set_axis_off()
    plot_field(axes[1], f)
    for ax, i in zip(axes[2:], range(3)):
        lim = max(float(np.abs(f[..., i]).max()), 1e-9)
        im = ax.imshow(f[..., i], cmap="RdBu_r", vmin=-lim, vmax=lim)
        for (r, c), v in np.ndenumerate(f[..., i]):
            ax.text(c, r, f"{v:.0f}", ha="center", va="center", fontsize=7)
        ax.set_title(f"B_{AXES[i]} [uT] (row 0 = +y)")
        ax.set_xticks(range(4))
        ax.set_yticks(range(4))
        fig.colorbar(im, ax=ax, shrink=0.8)
    if title:
        fig.suptitle(title)
    if path is not None:
        path = figure_path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path, dpi=90)
        plt.close(fig)
    return fig


def figure_path(path: str | Path) -> Path:
    """The file matplotlib's ``savefig(path)`` writes: ``path``, with ``.png`` appended when it has no suffix."""
    path = Path(path)
    return path if path.suffix else path.with_name(path.name + ".png")
