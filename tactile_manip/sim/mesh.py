"""Triangle mesh (STL, OBJ, PLY, ...) -> protrusion heightmap of its pad-facing surface.

The pad-facing surface of a mesh is its lowest surface along the mesh's z axis (the object is pressed
down onto the pad). Triangles are rasterised into a z-buffer on a regular xy grid with a vectorised
barycentric test; each pixel keeps the lowest z of the triangles covering its centre, and the protrusion
is ``-z_min`` (NaN where no triangle covers the pixel). ``trimesh`` is imported only when a file is read.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tactile_manip.checks import check_finite_scalar
from tactile_manip.errors import MeshError
from tactile_manip.extras import require

MAX_GRID_PX = 4000          # largest heightmap side, pixels
_CHUNK_PX = 2_000_000       # candidate pixels tested per vectorised batch (bounds memory to ~100 MB)
_EDGE_TOL = 1e-9            # barycentric slack so pixel centres on shared edges are not lost


def heightmap_from_mesh(path: str | Path, *, pixel_mm: float = 0.05) -> tuple[np.ndarray, float]:
    """Rasterise the lowest surface of the mesh in ``path`` into a protrusion heightmap.

    Returns ``(height_mm, pixel_mm)``: ``height_mm`` is float64 (H, W) in image layout (row 0 at +y,
    column 0 at -x), centred on the mesh's xy bounding box, with a one-pixel NaN border.
    Raises ``MeshError`` for unreadable, empty, non-finite or degenerate meshes, ``ValueError`` when
    ``pixel_mm`` would need a grid wider than ``MAX_GRID_PX`` and ``ImportError`` without trimesh.
    """
    pixel_mm = check_finite_scalar("pixel_mm", pixel_mm, low=0.0, low_open=True)
    tris = _load_triangles(Path(path))  # (T, 3, 3) mm
    lo, hi = tris[:, :, :2].min(axis=(0, 1)), tris[:, :, :2].max(axis=(0, 1))
    shape = np.ceil((hi - lo) / pixel_mm).astype(int) + 3  # (W, H) with a NaN margin
    if shape.max() > MAX_GRID_PX:
        need = float((hi - lo).max() / (MAX_GRID_PX - 3))
        raise ValueError(f"pixel_mm = {pixel_mm} gives a {shape[1]}x{shape[0]} grid for mesh {path}; "
                         f"at most {MAX_GRID_PX} px per side is allowed: use pixel_mm >= {need:.4g}")
    centre = (lo + hi) / 2.0
    zmin = _rasterise_min_z(tris, centre, pixel_mm, width=int(shape[0]), height=int(shape[1]))
    height = -zmin
    if not np.isfinite(height).any():
        raise MeshError(f"mesh {path} covers no pixel centre at pixel_mm = {pixel_mm}: use a smaller pixel")
    return height, pixel_mm


def _load_triangles(path: Path) -> np.ndarray:
    """Read ``path`` with trimesh and return its triangles as float64 (T, 3, 3) in mm."""
    trimesh = require("trimesh", "reading meshes")
    if not path.is_file():
        raise MeshError(f"mesh file {path} does not exist or is not a file")
    try:
        # process=False keeps NaN vertices visible instead of silently dropping their faces
        mesh = trimesh.load(str(path), force="mesh", process=False)
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
        faces = np.asarray(mesh.faces, dtype=np.int64)
    except Exception as e:  # trimesh raises many types for corrupt files
        raise MeshError(f"cannot read mesh file {path}: {type(e).__name__}: {e}") from e
    if faces.ndim != 2 or faces.shape[0] == 0 or faces.shape[1] != 3:
        raise MeshError(f"mesh file {path} has no triangles (empty, corrupt or not a mesh format)")
    if not np.isfinite(vertices).all():
        raise MeshError(f"mesh file {path} has non-finite (NaN or inf) vertex coordinates")
    tris = vertices[faces]
    if np.ptp(tris[:, :, 0]) <= 0.0 or np.ptp(tris[:, :, 1]) <= 0.0 or not (_signed_area2(tris) != 0).any():
        raise MeshError(f"mesh file {path} is degenerate: its triangles enclose no area seen along z")
    return tris


def _signed_area2(tris: np.ndarray) -> np.ndarray:
    """Twice the signed xy area of each triangle of (T, 3, 3); shape (T,)."""
    a, b, c = tris[:, 0, :2], tris[:, 1, :2], tris[:, 2, :2]
    return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])


def _rasterise_min_z(tris: np.ndarray, centre: np.ndarray, pixel_mm: float, *, width: int,
                     height: int) -> np.ndarray:
    """Lowest z of the triangles (T, 3, 3) at each pixel centre of an (height, width) grid; NaN if none."""
    tris = tris[_signed_area2(tris) != 0]  # vertical triangles have no interior seen along z
    # pixel coordinates: column from x, row from y (row 0 is +y)
    col = (tris[:, :, 0] - centre[0]) / pixel_mm + (width - 1) / 2.0
    row = (height - 1) / 2.0 - (tris[:, :, 1] - centre[1]) / pixel_mm
    c0 = np.clip(np.ceil(col.min(axis=1) - 1e-7), 0, width - 1).astype(np.int64)
    c1 = np.clip(np.floor(col.max(axis=1) + 1e-7), 0, width - 1).astype(np.int64)
    r0 = np.clip(np.ceil(row.min(axis=1) - 1e-7), 0, height - 1).astype(np.int64)
    r1 = np.clip(np.floor(row.max(axis=1) + 1e-7), 0, height - 1).astype(np.int64)
    tiles = _split_tiles(np.arange(len(tris)), r0, r1 - r0 + 1, c0, c1 - c0 + 1)
    zbuf = np.full(height * width, np.inf)
    area = tiles[2] * tiles[4]
    batch = (np.cumsum(area) - area) // _CHUNK_PX  # batch id; each batch tests <= 2 * _CHUNK_PX pixels
    for sel in np.split(np.arange(len(area)), np.flatnonzero(np.diff(batch)) + 1):
        _rasterise_tiles(tuple(t[sel] for t in tiles), col, row, tris[:, :, 2], zbuf, width)
    zbuf[np.isinf(zbuf)] = np.nan
    return zbuf.reshape(height, width)


def _split_tiles(tri: np.ndarray, r0: np.ndarray, nr: np.ndarray, c0: np.ndarray,
                 nc: np.ndarray) -> tuple[np.ndarray, ...]:
    """Cut each triangle's pixel box into row bands of at most ``_CHUNK_PX`` pixels.

    Returns ``(tri, r0, nr, c0, nc)`` per band, all int64 of equal length.
    """
    rows_per_band = np.maximum(1, _CHUNK_PX // np.maximum(nc, 1))
    n_bands = -(-nr // rows_per_band)
    first = np.repeat(np.cumsum(n_bands) - n_bands, n_bands)
    k = np.arange(n_bands.sum()) - first  # band index within its triangle
    idx = np.repeat(np.arange(len(tri)), n_bands)
    band_r0 = r0[idx] + k * rows_per_band[idx]
    band_nr = np.minimum(rows_per_band[idx], r0[idx] + nr[idx] - band_r0)
    keep = (band_nr > 0) & (nc[idx] > 0)
    return tri[idx][keep], band_r0[keep], band_nr[keep], c0[idx][keep], nc[idx][keep]


def _rasterise_tiles(tiles: tuple[np.ndarray, ...], col: np.ndarray, row: np.ndarray, z: np.ndarray,
                     zbuf: np.ndarray, width: int) -> None:
    """Test every pixel of the tiles against its triangle and lower ``zbuf`` (flat) in place."""
    tri, r0, nr, c0, nc = tiles
    area = nr * nc
    t = np.repeat(tri, area)
    k = np.arange(area.sum()) - np.repeat(np.cumsum(area) - area, area)
    pc = np.repeat(c0, area) + k % np.repeat(nc, area)
    pr = np.repeat(r0, area) + k // np.repeat(nc, area)
    (x0, x1, x2), (y0, y1, y2) = col[t].T, row[t].T
    det = (y1 - y2) * (x0 - x2) + (x2 - x1) * (y0 - y2)
    l0 = ((y1 - y2) * (pc - x2) + (x2 - x1) * (pr - y2)) / det
    l1 = ((y2 - y0) * (pc - x2) + (x0 - x2) * (pr - y2)) / det
    l2 = 1.0 - l0 - l1
    inside = (l0 >= -_EDGE_TOL) & (l1 >= -_EDGE_TOL) & (l2 >= -_EDGE_TOL)
    zt = z[t[inside]]
    zp = l0[inside] * zt[:, 0] + l1[inside] * zt[:, 1] + l2[inside] * zt[:, 2]
    np.minimum.at(zbuf, pr[inside] * width + pc[inside], zp)
