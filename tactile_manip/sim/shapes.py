"""Built-in indenters: the paper's Allen key and letter "R", rods, a procedural family, and a name registry.

Each shape is an :class:`~tactile_manip.sim.objects.Indenter` sampled at 0.05 mm with its reference point at a
natural place (bar axis, glyph centre). Heights are measured from a natural datum (bar axis, base plate), so
only differences of protrusion are physical. ``make_indenter(name, **kwargs)`` looks shapes up in
:data:`SHAPES`.
"""

from __future__ import annotations

import functools
import inspect
import math
from collections.abc import Callable

import numpy as np
from scipy import ndimage

from tactile_manip.checks import check_choice, check_finite_scalar
from tactile_manip.sim.objects import DEFAULT_PIXEL_MM, Indenter

ROD_KINDS = ("cylinder", "hex", "square")


# ---------------------------------------------------------------- sampling helpers

def _grid(x_range: tuple[float, float], y_range: tuple[float, float],
          pixel_mm: float) -> tuple[np.ndarray, np.ndarray, tuple[float, float]]:
    """Pixel centres (H, W) covering the box in reference coordinates, and the matching ``origin_mm``."""
    nx = int(round((x_range[1] - x_range[0]) / pixel_mm)) + 1
    ny = int(round((y_range[1] - y_range[0]) / pixel_mm)) + 1
    cx, cy = (x_range[0] + x_range[1]) / 2.0, (y_range[0] + y_range[1]) / 2.0
    xs = cx + (np.arange(nx) - (nx - 1) / 2.0) * pixel_mm
    ys = cy + ((ny - 1) / 2.0 - np.arange(ny)) * pixel_mm
    x, y = np.meshgrid(xs, ys)
    return x, y, (0.0 - cx, 0.0 - cy)


def _extrude(inside_mm: np.ndarray, height_mm: float, fillet_mm: float) -> np.ndarray:
    """Flat-topped prism from a distance-inside field (mm, < 0 outside): top edge rounded by ``fillet_mm``."""
    d = np.clip(inside_mm, 0.0, None)
    if fillet_mm > 0:
        t = np.clip(fillet_mm - d, 0.0, None)
        top = height_mm - fillet_mm + np.sqrt(np.clip(fillet_mm**2 - t**2, 0.0, None))
    else:
        top = np.full_like(d, height_mm)
    return np.where(inside_mm >= 0, top, np.nan)


def _segment_distance(x: np.ndarray, y: np.ndarray, a: tuple[float, float], b: tuple[float, float]) -> np.ndarray:
    """Distance (mm) from points to the segment a-b."""
    ax, ay = a
    vx, vy = b[0] - ax, b[1] - ay
    t = np.clip(((x - ax) * vx + (y - ay) * vy) / max(vx * vx + vy * vy, 1e-12), 0.0, 1.0)
    return np.hypot(x - ax - t * vx, y - ay - t * vy)


def _hex_profile(y: np.ndarray, across_flats_mm: float) -> np.ndarray:
    """Protrusion above the axis of a hex bar lying on a flat face, across the bar (NaN beyond the corners)."""
    side = across_flats_mm / math.sqrt(3.0)
    depth = math.sqrt(3.0) * np.clip(np.abs(y) - side / 2.0, 0.0, None)  # 60-degree flanks
    return np.where(np.abs(y) <= side + 1e-9, across_flats_mm / 2.0 - depth, np.nan)


_PROFILES: dict[str, Callable[[np.ndarray, float], np.ndarray]] = {
    "cylinder": lambda y, d: np.where(np.abs(y) <= d / 2, np.sqrt(np.clip(d * d / 4 - y * y, 0, None)), np.nan),
    "hex": _hex_profile,
    "square": lambda y, a: np.where(np.abs(y) <= a / 2 + 1e-9, a / 2, np.nan),
}
_ROD_NAMES = {"cylinder": "cylinder", "hex": "hex_bar", "square": "square_bar"}
_HALF_WIDTH = {"cylinder": 0.5, "hex": 1.0 / math.sqrt(3.0), "square": 0.5}  # footprint half width / size


def _polygon_inside(x: np.ndarray, y: np.ndarray, verts: np.ndarray) -> np.ndarray:
    """Signed distance (mm) to a closed polygon (V, 2): positive inside (even-odd rule)."""
    dist = np.full(x.shape, np.inf)
    inside = np.zeros(x.shape, dtype=bool)
    for (ax, ay), (bx, by) in zip(verts, np.roll(verts, -1, axis=0)):
        dist = np.minimum(dist, _segment_distance(x, y, (ax, ay), (bx, by)))
        crosses = (ay > y) != (by > y)
        x_cross = ax + (y - ay) * (bx - ax) / np.where(by == ay, 1.0, by - ay)
        inside ^= crosses & (x < x_cross)
    return np.where(inside, dist, -dist)


def _check_seed(seed: object) -> None:
    """Refuse a seed of a procedural family that is not a non-negative integer (ValueError)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")


def _indenter(height_mm: np.ndarray, origin_mm: tuple[float, float], name: str) -> Indenter:
    return Indenter(height_mm, DEFAULT_PIXEL_MM, name=name, origin_mm=origin_mm)


# ---------------------------------------------------------------- built-in shapes

def allen_key(*, across_flats_mm: float = 4.0, long_arm_mm: float = 30.0, short_arm_mm: float = 10.0,
              bend_radius_mm: float | None = None) -> Indenter:
    """Hex (Allen) key lying on a flat face, long arm along local +x, L bend turning away from the pad.

    ``bend_radius_mm`` is the radius of the bar axis in the bend (default ``across_flats_mm``); the short
    arm rises away from the pad so only its bend shows. Reference point: on the bar axis 6 mm inside the
    outside of the bend; heights measured from the bar axis (flat face at ``across_flats_mm / 2``).
    """
    a = check_finite_scalar("across_flats_mm", across_flats_mm, low=1.5, high=10.0)
    r = a if bend_radius_mm is None else check_finite_scalar("bend_radius_mm", bend_radius_mm, low=a / 2, high=4 * a)
    reach = r + a / 2  # bend centre to the outside of the bend
    length = check_finite_scalar("long_arm_mm", long_arm_mm, low=reach + a, high=150.0)
    check_finite_scalar("short_arm_mm", short_arm_mm, low=reach, high=150.0)
    x_out, px = 6.0, DEFAULT_PIXEL_MM
    half = a / math.sqrt(3.0) + px
    x, y, origin = _grid((x_out - length, x_out + px), (-half, half), px)
    t = _hex_profile(y, a)  # height of the section's pad-facing edge above the axis
    u = x - (x_out - reach)  # distance past the start of the bend
    with np.errstate(invalid="ignore"):
        bent = np.sqrt((r + t) ** 2 - u**2) - r  # NaN beyond the outside of the bend
    height = np.where(u <= 0, t, bent)
    return _indenter(height, origin, "allen_key")


def letter_r(*, glyph_height_mm: float = 12.0, stroke_mm: float = 2.0, relief_mm: float = 2.0,
             fillet_mm: float = 0.2) -> Indenter:
    """Upright capital "R" raised ``relief_mm`` above a flat base plate (protrusion 0 on the plate).

    Stem, bowl (two bars and a half ring) and straight diagonal leg of width ``stroke_mm``; the glyph top
    edge is rounded by ``fillet_mm``. Reference point: the centre of the glyph's box.
    """
    h = check_finite_scalar("glyph_height_mm", glyph_height_mm, low=4.0, high=25.0)
    w = check_finite_scalar("stroke_mm", stroke_mm, low=0.5, high=h / 4)
    relief = check_finite_scalar("relief_mm", relief_mm, low=0.2, high=5.0)
    fillet = check_finite_scalar("fillet_mm", fillet_mm, low=0.0, high=min(w / 2, relief) * 0.99)
    plate = max(30.0, h + 12.0) / 2
    x, y, origin = _grid((-plate, plate), (-plate, plate), DEFAULT_PIXEL_MM)
    mask = _r_mask(x, y, h, w)
    inside = ndimage.distance_transform_edt(mask) * DEFAULT_PIXEL_MM - DEFAULT_PIXEL_MM / 2
    height = np.where(mask, _extrude(inside, relief, fillet), 0.0)
    return _indenter(height, origin, "letter_r")


def _r_mask(x: np.ndarray, y: np.ndarray, h: float, w: float) -> np.ndarray:
    """Boolean mask of an upright "R" of height ``h`` and stroke ``w`` centred on the origin (mm)."""
    half_w, top, bottom = 0.35 * h, h / 2, -h / 2
    y_bowl = -0.02 * h - w / 2  # bottom of the middle bar = bottom of the bowl
    r_out = (top - y_bowl) / 2
    xc, yc = half_w - 0.05 * h - r_out, (top + y_bowl) / 2
    stem = (x >= -half_w) & (x <= -half_w + w) & (np.abs(y) <= top)
    bars = (x >= -half_w) & (x <= xc) & (((y <= top) & (y >= top - w)) | ((y >= y_bowl) & (y <= y_bowl + w)))
    rho = np.hypot(x - xc, y - yc)
    arc = (x >= xc) & (rho <= r_out) & (rho >= r_out - w)
    p1, p2 = np.array([-half_w + w + 0.07 * h, y_bowl + w / 2]), np.array([half_w - 0.6 * w, bottom])
    n = np.array([p2[1] - p1[1], p1[0] - p2[0]]) / np.hypot(*(p2 - p1))  # unit normal of the leg axis
    leg = (np.abs((x - p1[0]) * n[0] + (y - p1[1]) * n[1]) <= w / 2) & (y >= bottom) & (y <= y_bowl + w)
    return stem | bars | arc | leg


def rod(kind: str, *, size_mm: float = 4.0, length_mm: float = 30.0) -> Indenter:
    """Straight bar along local x with flat-cut ends, lying on a face; reference point at its centre.

    ``kind``: "cylinder" (``size_mm`` = diameter), "hex" (across flats) or "square" (side).
    Heights measured from the bar axis.
    """
    check_choice("kind", kind, ROD_KINDS)
    size = check_finite_scalar("size_mm", size_mm, low=2.0, high=8.0)
    length = check_finite_scalar("length_mm", length_mm, low=size, high=150.0)
    px = DEFAULT_PIXEL_MM
    half_x, half_y = length / 2 + px, _HALF_WIDTH[kind] * size + px
    x, y, origin = _grid((-half_x, half_x), (-half_y, half_y), px)
    height = np.where(np.abs(x) <= length / 2 + 1e-9, _PROFILES[kind](y, size), np.nan)
    return _indenter(height, origin, _ROD_NAMES[kind])


def flat_bar(*, width_mm: float = 12.0, thickness_mm: float = 3.0, fillet_mm: float = 0.5,
             length_mm: float = 40.0) -> Indenter:
    """A flat bar (a strip of rectangular section) lying on its wide face, along local x, edges rounded by
    ``fillet_mm``; reference point at the centre of the face. Heights measured from the bar's mid-plane.

    Up to 20 mm wide, as wide as the pad: a small tilt about its axis or its length leaves only one edge or one
    end in contact, the case a short footprint cannot resolve.
    """
    width = check_finite_scalar("width_mm", width_mm, low=2.0, high=20.0)
    thick = check_finite_scalar("thickness_mm", thickness_mm, low=0.5, high=10.0)
    fillet = check_finite_scalar("fillet_mm", fillet_mm, low=0.0, high=min(width, thick) / 2)
    length = check_finite_scalar("length_mm", length_mm, low=width, high=150.0)
    px = DEFAULT_PIXEL_MM
    x, y, origin = _grid((-length / 2 - px, length / 2 + px), (-width / 2 - px, width / 2 + px), px)
    inside = np.minimum(width / 2 - np.abs(y), length / 2 - np.abs(x))
    face = _extrude(np.where(np.abs(x) <= length / 2 + 1e-9, width / 2 - np.abs(y), -1.0), thick / 2, fillet)
    return _indenter(np.where(inside >= -1e-9, face, np.nan), origin, "flat_bar")


def procedural_bar(seed: int, *, length_mm: float = 40.0) -> Indenter:
    """A seeded family of long straight bars for learning a contact's axis: a cross-section drawn per seed,
    lying along local x, reference point on its axis.

    The section's upper outline is a superellipse ``(|y| / a)^p + (z / b)^p = 1`` with ``p`` in 1.5-8 (from
    lens-like to nearly rectangular), half width ``a`` 1-10 mm and half height ``b`` 0.5-4 mm; about a third of
    the seeds cut its top flat at 40-90 % of ``b`` (a flat face with rounded shoulders). The family contains no
    section of the built-in rods exactly, so those stay unseen shapes; the same seed always gives the same
    array.
    """
    _check_seed(seed)
    length = check_finite_scalar("length_mm", length_mm, low=10.0, high=150.0)
    rng = np.random.default_rng(int(seed))
    power, half_w, half_h = rng.uniform(1.5, 8.0), rng.uniform(1.0, 10.0), rng.uniform(0.5, 4.0)
    cut = rng.uniform(0.4, 0.9) * half_h if rng.random() < 1 / 3 else half_h
    px = DEFAULT_PIXEL_MM
    x, y, origin = _grid((-length / 2 - px, length / 2 + px), (-half_w - px, half_w + px), px)
    q = 1.0 - np.abs(y / half_w) ** power
    profile = np.minimum(half_h * np.clip(q, 0.0, None) ** (1.0 / power), cut)
    h = np.where((q >= 0) & (np.abs(x) <= length / 2 + 1e-9), profile, np.nan)
    return _indenter(h, origin, f"procedural_bar_{int(seed)}")


#: regular sections of :func:`procedural_prism` (sides); the rest of its seeds are strips
PRISM_SIDES = (3, 4, 5, 6, 8)


def procedural_prism(seed: int) -> Indenter:
    """A seeded family of sharp-edged straight bars of any length, lying on a face along local x, reference
    point at the section's centre: what :func:`procedural_bar`'s rounded sections and long bars leave out.

    Half the seeds have a regular section (3, 4, 5, 6 or 8 sides, 2-12 mm across corners), half a
    strip (2-20 mm wide, 0.5-5 mm thick, edges rounded by 0-0.3 mm); each bar is 12-50 mm long with flat-cut
    ends, so a bar shorter than the pad's diagonal, or one off centre, ends on the pad. The family contains no
    section and length of the built-in rods and flat bars exactly; the same seed always gives the same array.
    """
    _check_seed(seed)
    rng = np.random.default_rng([int(seed), 31])
    length = rng.uniform(12.0, 50.0)
    px = DEFAULT_PIXEL_MM
    if rng.random() < 0.5:
        sides = int(rng.choice(PRISM_SIDES))
        radius = rng.uniform(1.0, 6.0)                     # centre to corner
        apothem = radius * math.cos(math.pi / sides)
        normals = math.pi / 2 + 2 * math.pi * np.arange(sides) / sides   # the face on the pad has normal +z
        corners = normals[:, None] + np.array([-math.pi, math.pi]) / sides
        half_w = float(np.max(np.abs(np.cos(corners)))) * radius
        x, y, origin = _grid((-length / 2 - px, length / 2 + px), (-half_w - px, half_w + px), px)
        upper = np.sin(normals) > 1e-9
        lines = (apothem - y[..., None] * np.cos(normals[upper])) / np.sin(normals[upper])
        profile = np.where(np.abs(y) <= half_w + 1e-9, lines.min(axis=-1), np.nan)
    else:
        width, thick = rng.uniform(2.0, 20.0), rng.uniform(0.5, 5.0)
        fillet = rng.uniform(0.0, min(0.3, thick / 2))
        x, y, origin = _grid((-length / 2 - px, length / 2 + px), (-width / 2 - px, width / 2 + px), px)
        profile = _extrude(width / 2 - np.abs(y), thick / 2, fillet)
    return _indenter(np.where(np.abs(x) <= length / 2 + 1e-9, profile, np.nan), origin, f"procedural_prism_{int(seed)}")


def ridge(*, angle_deg: float = 60.0, tip_radius_mm: float = 0.1, height_mm: float = 3.0,
          length_mm: float = 30.0) -> Indenter:
    """A knife-edge: a straight wedge bar along local x with apex angle ``angle_deg`` and a tip rounded to
    ``tip_radius_mm``, standing on its base; reference point at the centre of the edge.

    The flanks meet the pad along a line contact far narrower than the taxel pitch: the hardest contact for
    a 4x4 grid to resolve (heights measured from the base; ``height_mm`` is that of the sharp apex, the rounded
    tip lies ``r (1 / sin(angle / 2) - 1)`` below it; footprint ``2 height tan(angle / 2)`` wide).
    """
    angle = math.radians(check_finite_scalar("angle_deg", angle_deg, low=20.0, high=150.0))
    radius = check_finite_scalar("tip_radius_mm", tip_radius_mm, low=0.0, high=2.0)
    height = check_finite_scalar("height_mm", height_mm, low=0.5, high=10.0)
    length = check_finite_scalar("length_mm", length_mm, low=2.0, high=150.0)
    half = angle / 2
    px = DEFAULT_PIXEL_MM
    half_x, half_y = length / 2 + px, height * math.tan(half) + px
    x, y, origin = _grid((-half_x, half_x), (-half_y, half_y), px)
    flank = height - np.abs(y) / math.tan(half)
    centre = height - radius / math.sin(half)          # the tip circle touches both flanks
    tip = centre + np.sqrt(np.clip(radius**2 - y**2, 0.0, None))
    profile = np.where(np.abs(y) <= radius * math.cos(half), tip, flank)
    h = np.where((np.abs(x) <= length / 2 + 1e-9) & (profile >= 0), profile, np.nan)
    return _indenter(h, origin, "ridge")


# ---------------------------------------------------------------- procedural (unseen) shapes

def _placed(rng: np.random.Generator, x: np.ndarray, y: np.ndarray, size: float) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates (mm) in a frame with a random centre (within +-0.15 size) and random orientation."""
    cx, cy = rng.uniform(-0.15, 0.15, size=2) * size
    c, s = np.cos(rng.uniform(0, np.pi)), np.sin(rng.uniform(0, np.pi))
    return c * (x - cx) + s * (y - cy), -s * (x - cx) + c * (y - cy)


def _dome(rng: np.random.Generator, u: np.ndarray, v: np.ndarray, size: float, height: float) -> np.ndarray:
    a, b = rng.uniform(0.12, 0.35, size=2) * size
    q = 1.0 - (u / a) ** 2 - (v / b) ** 2
    return np.where(q >= 0, height * np.sqrt(np.clip(q, 0, None)), np.nan)


def _bar(rng: np.random.Generator, u: np.ndarray, v: np.ndarray, size: float) -> np.ndarray:
    half_len, width = rng.uniform(0.15, 0.3) * size, rng.uniform(0.08, 0.2) * size
    return width / 2 - _segment_distance(u, v, (-half_len, 0.0), (half_len, 0.0))


def _ring(rng: np.random.Generator, u: np.ndarray, v: np.ndarray, size: float) -> np.ndarray:
    radius, width = rng.uniform(0.15, 0.28) * size, rng.uniform(0.06, 0.14) * size
    return width / 2 - np.abs(np.hypot(u, v) - radius)


def _cross(rng: np.random.Generator, u: np.ndarray, v: np.ndarray, size: float) -> np.ndarray:
    arm, half_w = rng.uniform(0.15, 0.35) * size, rng.uniform(0.04, 0.1) * size
    return np.maximum(np.minimum(arm - np.abs(u), half_w - np.abs(v)), np.minimum(half_w - np.abs(u), arm - np.abs(v)))


def _star(rng: np.random.Generator, u: np.ndarray, v: np.ndarray, size: float) -> np.ndarray:
    n = int(rng.integers(4, 9))
    radii = np.tile([rng.uniform(0.2, 0.35) * size, 0.0], n)
    radii[1::2] = radii[0] * rng.uniform(0.35, 0.65)
    angles = np.arange(2 * n) * np.pi / n
    return _polygon_inside(u, v, np.stack([radii * np.cos(angles), radii * np.sin(angles)], axis=1))


def _stroke(rng: np.random.Generator, u: np.ndarray, v: np.ndarray, size: float) -> np.ndarray:
    pts = rng.uniform(-0.3, 0.3, size=(int(rng.integers(3, 6)), 2)) * size
    dist = np.min([_segment_distance(u, v, tuple(a), tuple(b)) for a, b in zip(pts[:-1], pts[1:])], axis=0)
    return rng.uniform(0.05, 0.12) * size - dist


# distance-inside fields (mm, > 0 inside) extruded into flat-topped prisms with a rounded top edge
_PRISMS = (_bar, _ring, _cross, _star, _stroke)


def procedural(seed: int, *, size_mm: float = 14.0) -> Indenter:
    """One of a seeded family of unseen test shapes inside a ``size_mm`` square, reference at its centre.

    Union of 1-3 random parts (domes / ellipsoidal caps, rounded bars, rings, crosses, star prisms,
    polyline strokes), each 0.5-2.5 mm high, on a base plate (protrusion 0) for about half the seeds.
    The same seed always gives the same array.
    """
    _check_seed(seed)
    size = check_finite_scalar("size_mm", size_mm, low=4.0, high=30.0)
    rng = np.random.default_rng(int(seed))
    x, y, origin = _grid((-size / 2, size / 2), (-size / 2, size / 2), DEFAULT_PIXEL_MM)
    height = np.zeros_like(x) if rng.random() < 0.5 else np.full_like(x, np.nan)
    for _ in range(int(rng.integers(1, 4))):
        part_height = rng.uniform(0.5, 2.5)
        u, v = _placed(rng, x, y, size)
        k = int(rng.integers(len(_PRISMS) + 1))
        if k == len(_PRISMS):
            part = _dome(rng, u, v, size, part_height)
        else:
            inside = _PRISMS[k](rng, u, v, size)
            part = _extrude(inside, part_height, rng.uniform(0.0, 0.5) * min(part_height, 0.4))
        height = np.fmax(height, part)
    return _indenter(height, origin, f"procedural_{int(seed)}")


def procedural_sharp(seed: int, *, size_mm: float = 14.0) -> Indenter:
    """A seeded family of sharp-edged shapes: the parts of :func:`procedural` (bars, rings, crosses, stars,
    strokes) roofed with flanks at 15-60 degrees from vertical instead of flat tops with rounded edges, so a
    bar or stroke becomes a knife ridge and a star or cross a pointed pyramid; 1-3 parts, 0.5-2.5 mm high.

    A separate family (not a flag of :func:`procedural`), so that every procedural seed keeps its shape.
    """
    _check_seed(seed)
    size = check_finite_scalar("size_mm", size_mm, low=4.0, high=30.0)
    rng = np.random.default_rng(int(seed))
    x, y, origin = _grid((-size / 2, size / 2), (-size / 2, size / 2), DEFAULT_PIXEL_MM)
    height = np.full_like(x, np.nan)
    parts = int(rng.integers(1, 4))
    for i in range(parts + 10):  # a part can miss the grid (a thin star): draw more until there is material
        if i >= parts and np.isfinite(height).any():
            break
        part_height, flank = rng.uniform(0.5, 2.5), math.radians(rng.uniform(15.0, 60.0))
        u, v = _placed(rng, x, y, size)
        inside = _PRISMS[int(rng.integers(len(_PRISMS)))](rng, u, v, size)
        roof = np.minimum(part_height, inside / math.tan(flank))   # slope of the flank: 1 / tan(flank)
        height = np.fmax(height, np.where(inside > 0, roof, np.nan))
    return _indenter(height, origin, f"procedural_sharp_{int(seed)}")


# ---------------------------------------------------------------- registry

SHAPES: dict[str, Callable[..., Indenter]] = {
    "allen_key": allen_key,
    "letter_r": letter_r,
    "cylinder": functools.partial(rod, "cylinder"),
    "hex_bar": functools.partial(rod, "hex"),
    "square_bar": functools.partial(rod, "square"),
    "procedural": procedural,
    "ridge": ridge,
    "procedural_sharp": procedural_sharp,
    "flat_bar": flat_bar,
    "procedural_bar": procedural_bar,
    "procedural_prism": procedural_prism,
}


def make_indenter(name: str, **kwargs: object) -> Indenter:
    """Build the built-in shape called ``name`` (a key of ``SHAPES``) with its keyword arguments."""
    check_shape_arguments(name, kwargs)
    return SHAPES[name](**kwargs)


def check_shape_arguments(name: str, kwargs: dict[str, object], *, where: str = "") -> None:
    """Raise ValueError when ``name`` is not a shape of SHAPES or ``kwargs`` do not fit its arguments.

    The message names the unknown or missing keys and the arguments the shape accepts (``where`` prefixes
    the keys, e.g. ``"objects.kwargs"``), so a config is refused when it is loaded, not mid-run.
    """
    try:
        factory = SHAPES[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown object {name!r}; known: {', '.join(SHAPES)}") from None
    params = inspect.signature(factory).parameters
    accepted = [p for p, v in params.items() if v.kind in (v.KEYWORD_ONLY, v.POSITIONAL_OR_KEYWORD)]
    unknown = sorted(set(kwargs) - set(accepted))
    missing = [p for p in accepted if params[p].default is inspect.Parameter.empty and p not in kwargs]
    if unknown or missing:
        prefix = f"{where}." if where else ""
        problem = (f"unknown argument(s) {', '.join(prefix + k for k in unknown)}" if unknown
                   else f"missing argument(s) {', '.join(prefix + k for k in missing)}")
        raise ValueError(f"{name}: {problem}; {name} accepts {', '.join(accepted) or 'no arguments'}")
