"""Candidate serial ports for the sensor board, with the USB bridges ESP32 boards commonly carry."""

from __future__ import annotations

from dataclasses import dataclass

from tactile_manip.sensors.serial_sensor import import_serial

# USB vendor:product ids of the serial bridges on ESP32 development boards (and the ESP32-S2/S3/C3 native USB).
KNOWN_BRIDGES: dict[tuple[int, int | None], str] = {
    (0x10C4, 0xEA60): "Silicon Labs CP210x (common on ESP32 boards)",
    (0x1A86, 0x7523): "WCH CH340 (common on ESP32 boards)",
    (0x1A86, 0x55D4): "WCH CH9102 (common on ESP32 boards)",
    (0x0403, 0x6001): "FTDI FT232R",
    (0x0403, 0x6015): "FTDI FT231X",
    (0x303A, None): "Espressif native USB (ESP32-S2/S3/C3)",
}


@dataclass(frozen=True)
class PortInfo:
    device: str          # path to open, e.g. /dev/ttyUSB0
    description: str     # what the OS says about it
    hwid: str            # USB ids and serial number, when USB
    bridge: str          # the known ESP32 bridge it looks like, or ""

    @property
    def likely(self) -> bool:
        """A USB serial bridge of a kind that ESP32 sensor boards carry."""
        return bool(self.bridge)


def bridge_name(vid: int | None, pid: int | None) -> str:
    """The known bridge for a USB vendor/product id, or ""."""
    if vid is None:
        return ""
    return KNOWN_BRIDGES.get((vid, pid)) or KNOWN_BRIDGES.get((vid, None), "")


def list_ports(*, include_all: bool = False) -> list[PortInfo]:
    """Serial ports, likely sensor boards first; without ``include_all`` only USB ports are listed."""
    import_serial()  # a clear ImportError naming the extra when pyserial is missing
    from serial.tools import list_ports as lp

    ports = []
    for p in lp.comports():
        if not include_all and p.vid is None:
            continue
        ports.append(PortInfo(device=p.device, description=p.description or "", hwid=p.hwid or "",
                              bridge=bridge_name(p.vid, p.pid)))
    return sorted(ports, key=lambda p: (not p.likely, p.device))
