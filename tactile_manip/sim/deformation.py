"""Displacement and displacement gradient inside the layer for a given surface pressure.

For a pressure ``p`` on a regular grid of cells, the bonded incompressible layer's internal displacement
``u(x, y, z)`` and its gradient ``du_i/dx_j`` follow per wavenumber from the vertical profile ``W(z)`` of
:mod:`tactile_manip.sim.layer`:

``u_z = W p``, ``u_h = i k_vec W' / k^2 p``, so ``du_z/dz = W'``, ``du_h/dz = i k_vec W'' / k^2 p``, and the
in-plane derivatives multiply by ``i k``. Fields are evaluated on the same cell grid with zero padding
(no wrap-around). Arrays use image layout: row 0 at +y, column 0 at -x.
"""

from __future__ import annotations

import functools

import numpy as np

from tactile_manip.sim.layer import vertical_profile


def layer_fields(pressure_mpa: np.ndarray, *, cell_mm: float, z_mm: np.ndarray, thickness_mm: float,
                 modulus_mpa: float) -> tuple[np.ndarray, np.ndarray]:
    """Displacement (mm) and its gradient at heights ``z_mm`` (pad frame, -h <= z <= 0) under ``pressure_mpa``.

    Args:
        pressure_mpa: (ny, nx) compressive pressure on the cell grid, MPa.
        cell_mm: cell pitch, mm.
        z_mm: (nz,) heights in the pad frame (the top surface is z = 0, the bonded base z = -h).

    Returns:
        ``u`` of shape (nz, ny, nx, 3), components (x, y, z) in mm, and ``grad`` of shape
        (nz, ny, nx, 3, 3) with ``grad[..., i, j] = du_i / dx_j``.
    """
    ny, nx = pressure_mpa.shape
    spectra = _transfer_spectra(ny, nx, float(cell_mm), tuple(float(z) for z in np.ravel(z_mm)),
                                float(thickness_mm))
    p_hat = np.fft.rfft2(pressure_mpa, s=(2 * ny, 2 * nx)) / modulus_mpa
    fields = np.fft.irfft2(spectra * p_hat, s=(2 * ny, 2 * nx))[..., :ny, :nx]
    fields = np.moveaxis(fields, 1, -1)  # (nz, ny, nx, 12)
    return fields[..., :3], fields[..., 3:].reshape(fields.shape[:-1] + (3, 3))


@functools.lru_cache(maxsize=8)
def _transfer_spectra(ny: int, nx: int, cell_mm: float, z_mm: tuple[float, ...], thickness_mm: float
                      ) -> np.ndarray:
    """Transfer functions (nz, 12, 2ny, nx+1) from pressure to (u, grad u) for E = 1 MPa, read-only.

    Order: u_x, u_y, u_z, then du_x/dx, /dy, /dz, du_y/dx, /dy, /dz, du_z/dx, /dy, /dz.
    """
    kx = 2.0 * np.pi * np.fft.rfftfreq(2 * nx, d=cell_mm)[None, :]
    ky = -2.0 * np.pi * np.fft.fftfreq(2 * ny, d=cell_mm)[:, None]  # row index grows towards -y
    k2 = kx**2 + ky**2
    inv_k2 = np.divide(1.0, k2, out=np.zeros_like(k2), where=k2 > 0)
    k = np.sqrt(k2)
    spectra = []
    for z in np.asarray(z_mm) + thickness_mm:  # height above the bonded base
        w, w1, w2 = vertical_profile(k, z, thickness_mm=thickness_mm, modulus_mpa=1.0)
        h1 = 1j * w1 * inv_k2  # u_h = h1 * k_vec * p
        h2 = 1j * w2 * inv_k2  # du_h/dz = h2 * k_vec * p
        spectra.append([h1 * kx, h1 * ky, w,                                       # u_x, u_y, u_z
                        1j * kx * h1 * kx, 1j * ky * h1 * kx, h2 * kx,             # du_x/dx, /dy, /dz
                        1j * kx * h1 * ky, 1j * ky * h1 * ky, h2 * ky,             # du_y/dx, /dy, /dz
                        1j * kx * w, 1j * ky * w, w1])                             # du_z/dx, /dy, /dz
    out = np.asarray(spectra)
    out.setflags(write=False)
    return out


def rotation_vectors(grad: np.ndarray) -> np.ndarray:
    """Infinitesimal rotation ``omega = curl(u) / 2`` (rad), shape ``grad.shape[:-2] + (3,)``."""
    return 0.5 * np.stack([grad[..., 2, 1] - grad[..., 1, 2],
                           grad[..., 0, 2] - grad[..., 2, 0],
                           grad[..., 1, 0] - grad[..., 0, 1]], axis=-1)


def rotate(vectors: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Rotate ``vectors`` (..., 3) by the exact rotation of angle ``|omega|`` about ``omega`` (Rodrigues).

    Not linearised: ``|omega|`` reaches ~0.7 rad at the contact edges, where ``v + omega x v`` would
    stretch the moment by ~20 %.
    """
    theta = np.linalg.norm(omega, axis=-1, keepdims=True)
    safe = np.where(theta > 0, theta, 1.0)
    axis = omega / safe
    cos, sin = np.cos(theta), np.sin(theta)
    dot = np.sum(axis * vectors, axis=-1, keepdims=True)
    return vectors * cos + np.cross(axis, vectors) * sin + axis * dot * (1.0 - cos)
