"""Slow changes of an idle pad: baseline tracking, temperature compensation and the stray-field warning.

:class:`BaselineState` holds the offset a sensor subtracts (``field = raw - offset``) and, opt-in through
:class:`~tactile_manip.sensors.config.DriftConfig`:

- **tracking**: after ``quiet_frames`` consecutive quiet frames (every channel of ``field`` within
  ``quiet_ut``), each further quiet frame moves the offset towards the raw field by ``rate``; one loud frame
  (a press) stops it until the pad has been quiet for ``quiet_frames`` frames again, so contacts are never
  learnt into the baseline;
- **temperature**: with per-chip coefficients (uT/degC, x, y, z per chip in firmware order) and frames that
  carry temperatures, ``coeff * (T - T_baseline)`` is subtracted as well, ``T_baseline`` being the mean chip
  temperature while the baseline was taken;
- **stray field**: the median over chips of each axis of the newest field; when one moved by more than
  ``common_mode_ut``, every chip shifted together (a magnet or steel nearby, not a press, which moves a few
  chips): health reports ``stray_field``.

Without a baseline all of this is idle and ``field == raw``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from tactile_manip.sensors.config import DriftConfig
from tactile_manip.boards import Board


class BaselineState:
    """The offset in use and its drift counters (the sensor's lock is held around every call).

    Args:
        config: tracking, temperature and stray-field settings.
        layout: the board (for the reading shape, the used cells and the chip order of the coefficients).
    """

    def __init__(self, config: DriftConfig, layout: Board) -> None:
        self.config = config
        self.layout = layout
        self._mask = layout.mask
        self._coeff = None
        if config.temperature_coeff_ut_per_c:
            coeff = np.asarray(config.temperature_coeff_ut_per_c, np.float32)
            if coeff.size != 3 * layout.n_chips:
                raise ValueError(f"DriftConfig.temperature_coeff_ut_per_c has {coeff.size} values; the "
                                 f"{layout.name} board needs 3 per chip ({3 * layout.n_chips})")
            self._coeff = layout.reading_from_chips(coeff.reshape(-1, 3))  # turned into pad axes like the field
        self.set(None, None)

    def set(self, offset_ut: np.ndarray | None, temperature_c: np.ndarray | None) -> None:
        """Use a new offset (None: no baseline) taken at these chip temperatures (None: unknown)."""
        self.offset_ut = None if offset_ut is None else np.array(offset_ut, np.float32)
        self._initial = None if offset_ut is None else self.offset_ut.copy()
        self._t_ref = None if temperature_c is None else np.asarray(temperature_c, np.float32)
        self.quiet_run = 0
        self.updates = 0

    def field(self, raw_ut: np.ndarray, temperature_c: np.ndarray | None) -> np.ndarray:
        """``raw - offset`` (minus the temperature term where configured), read-only; ``raw`` without a baseline."""
        if self.offset_ut is None:
            return raw_ut
        field = raw_ut - self.offset_ut
        if self._coeff is not None and self._t_ref is not None and temperature_c is not None:
            dt = np.nan_to_num(temperature_c - self._t_ref)[..., None]  # unused cells carry NaN temperatures
            field -= self._coeff * dt
        field.flags.writeable = False
        return field

    def observe(self, raw_ut: np.ndarray, field_ut: np.ndarray) -> None:
        """Apply the tracking rule to one published frame (no-op unless tracking is on and a baseline is set)."""
        if not self.config.track or self.offset_ut is None:
            return
        if float(np.abs(field_ut).max()) >= self.config.quiet_ut:
            self.quiet_run = 0
            return
        self.quiet_run += 1
        if self.quiet_run > self.config.quiet_frames:
            self.offset_ut += np.float32(self.config.rate) * (raw_ut - self.offset_ut)
            self.updates += 1

    def health(self, newest_field_ut: np.ndarray | None) -> dict[str, Any]:
        """Health fields: tracking state, how far the offset moved, and the common-mode shift of the newest field."""
        tracking = self.config.track and self.offset_ut is not None and self.quiet_run > self.config.quiet_frames
        moved = 0.0 if self.offset_ut is None else float(np.abs(self.offset_ut - self._initial).max())
        common = (float("nan"),) * 3
        stray = False
        if self.offset_ut is not None and newest_field_ut is not None:
            med = np.median(np.asarray(newest_field_ut)[self._mask], axis=0)
            common = tuple(float(v) for v in med)
            stray = bool(np.abs(med).max() > self.config.common_mode_ut)
        return {"baseline_tracking": tracking, "baseline_updates": self.updates, "baseline_moved_ut": moved,
                "common_mode_ut": common, "stray_field": stray}
