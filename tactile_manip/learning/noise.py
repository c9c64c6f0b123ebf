"""Chip noise drawn afresh for simulated training presses.

A simulated dataset stores each press's reading once, with one draw of the chips' drift and noise. At light
forces that draw is a large part of the reading, and a network trained on a few tens of thousands of presses
learns the draws. Datasets made by ``tactile-manip simulate`` also store the reading without drift, noise and
quantisation (``field_clean_ut``) and, on drawn sensors, each press's noise and drift levels
(``sensor_params``), so a training epoch can read every press through new chips:

    reading = LSB * round((clean + drift + noise) / LSB),  drift ~ N(0, drift_ut) per channel,
                                                          noise ~ N(0, noise_xy_ut | noise_z_ut) per channel,

as :class:`tactile_manip.sim.chip.ChipArray` measures one frame. Presses with a channel at the register's rail
keep their stored reading (the rail depends on the baseline, which the clean reading has taken out).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tactile_manip.data import PairedDataset
from tactile_manip.errors import DatasetError

#: dotted names of the drawn sensor parameters a redraw needs, as the dataset's ``sensor_params`` records them
NOISE_PARAMS = ("chip.noise_xy_ut", "chip.noise_z_ut", "chip.drift_ut")


@dataclass(frozen=True)
class ChipNoise:
    """What a redraw needs for N presses (see the module docstring)."""

    clean_ut: np.ndarray      # (N, R, C, 3) float32 reading without drift, noise and quantisation, uT
    stored_ut: np.ndarray     # (N, R, C, 3) float32 the dataset's reading, kept where ``at_rail``
    noise_ut: np.ndarray      # (N, 3) float32 noise std of the x, y, z channels, uT
    drift_ut: np.ndarray      # (N,) float32 drift std, uT
    lsb_ut: np.ndarray        # (3,) float32 register step of the x, y, z channels, uT
    at_rail: np.ndarray       # (N,) bool: a channel at the register's rail

    @classmethod
    def of(cls, data: PairedDataset, idx: np.ndarray, provenance: dict | None = None) -> ChipNoise:
        """The presses ``idx`` (ascending) of a simulated dataset, or of several joined
        (:func:`~tactile_manip.data.concatenate`: each part's presses with its own chip settings).

        Raises:
            DatasetError: the dataset has no clean readings (made before they were stored, or not simulated).
        """
        from tactile_manip.sim.dataset import recorded_sim_params

        idx = np.asarray(idx, dtype=np.int64)
        if not data.has("field_clean_ut"):
            raise DatasetError("drawing the chips' noise afresh needs the readings without noise "
                               "('field_clean_ut'), which `tactile-manip simulate` stores; this dataset has none: "
                               "simulate it again, or train with redraw_noise = false")
        provenance = data.provenance if provenance is None else provenance
        if "config" not in provenance and "parts" in provenance:
            ends = np.cumsum([part["samples"] for part in provenance["parts"]])
            return cls.concatenate([cls.of(data, idx[(idx >= end - part["samples"]) & (idx < end)], part)
                                    for part, end in zip(provenance["parts"], ends)])
        chip = recorded_sim_params(provenance["config"]).chip
        levels = np.tile(np.array([[chip.noise_xy_ut, chip.noise_z_ut, chip.drift_ut]], np.float32), (len(idx), 1))
        names = list(provenance.get("sensor_param_names", []))
        if data.has("sensor_params"):
            drawn = data.extra("sensor_params")[idx]
            for k, name in enumerate(NOISE_PARAMS):
                if name in names:
                    levels[:, k] = drawn[:, names.index(name)]
        saturated = data.extra("saturated")[idx] if data.has("saturated") else np.zeros(data.readings[idx].shape, bool)
        return cls(clean_ut=data.extra("field_clean_ut")[idx].astype(np.float32),
                   stored_ut=data.readings[idx].astype(np.float32),
                   noise_ut=levels[:, [0, 0, 1]], drift_ut=levels[:, 2],
                   lsb_ut=np.array([chip.lsb_xy_ut, chip.lsb_xy_ut, chip.lsb_z_ut], np.float32),
                   at_rail=saturated.reshape(len(idx), -1).any(axis=1))

    def __len__(self) -> int:
        return len(self.clean_ut)

    def draw(self, rng: np.random.Generator) -> np.ndarray:
        """(N, R, C, 3) float32 readings through new drift and noise."""
        n = len(self)
        shape = self.clean_ut.shape
        drift = rng.standard_normal(shape, dtype=np.float32) * self.drift_ut.reshape(n, 1, 1, 1)
        noise = rng.standard_normal(shape, dtype=np.float32) * self.noise_ut.reshape(n, 1, 1, 3)
        out = np.rint((self.clean_ut + drift + noise) / self.lsb_ut) * self.lsb_ut
        out[self.at_rail] = self.stored_ut[self.at_rail]
        return out.astype(np.float32, copy=False)

    @staticmethod
    def concatenate(parts: list[ChipNoise]) -> ChipNoise:
        if any(not np.array_equal(p.lsb_ut, parts[0].lsb_ut) for p in parts):
            raise DatasetError("datasets with different chip register steps (lsb) cannot be trained together "
                               "with redraw_noise")
        return ChipNoise(**{k: np.concatenate([getattr(p, k) for p in parts]) for k in
                            ("clean_ut", "stored_ut", "noise_ut", "drift_ut", "at_rail")}, lsb_ut=parts[0].lsb_ut)
