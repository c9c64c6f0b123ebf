"""Candidate serial ports for a sensor board: the USB bridges of ESP32 boards and the native-USB boards.

A board behind a USB-serial bridge (CP210x, CH340/CH9102, FTDI: most ESP32 boards, the SuperMag firmware)
must be opened with DTR and RTS low, or it resets; a native-USB board (the SAMD21 of the ReSkin/AnySkin
boards, Espressif's own USB) writes nothing until the host raises DTR. :func:`list_ports` says which kind
each port looks like; :func:`device_for_serial_number` finds a board by its USB serial number, which
survives replugging (the /dev/tty* name does not).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from tactile_manip.errors import SensorDisconnectedError
from tactile_manip.sensors.serial_sensor import import_serial


@dataclass(frozen=True)
class UsbKind:
    name: str
    native_usb: bool  # the board's own USB (open with DTR high), not a bridge to a UART (DTR low)


# USB vendor:product ids (product None: any product of that vendor).
KNOWN_BOARDS: dict[tuple[int, int | None], UsbKind] = {
    (0x10C4, 0xEA60): UsbKind("Silicon Labs CP210x bridge (common on ESP32 boards)", False),
    (0x1A86, 0x7523): UsbKind("WCH CH340 bridge (common on ESP32 boards)", False),
    (0x1A86, 0x55D4): UsbKind("WCH CH9102 bridge (common on ESP32 boards)", False),
    (0x0403, 0x6001): UsbKind("FTDI FT232R bridge", False),
    (0x0403, 0x6010): UsbKind("FTDI FT2232 bridge", False),
    (0x0403, 0x6015): UsbKind("FTDI FT231X bridge", False),
    (0x303A, None): UsbKind("Espressif native USB (ESP32-S2/S3/C3)", True),
    (0x239A, None): UsbKind("Adafruit native USB (SAMD21 boards such as the Trinket/QT Py M0)", True),
    (0x2886, None): UsbKind("Seeed native USB (SAMD21 boards such as the XIAO)", True),
    (0x2341, None): UsbKind("Arduino native USB (SAMD21 boards such as the Zero, MKR, Nano 33 IoT)", True),
    (0x2A03, None): UsbKind("Arduino (arduino.org) native USB", True),
}


@dataclass(frozen=True)
class PortInfo:
    device: str          # path to open, e.g. /dev/ttyUSB0
    description: str     # what the OS says about it
    hwid: str            # USB ids and serial number, when USB
    bridge: str          # the known board kind it looks like, or ""
    serial_number: str = ""   # USB serial number ("" when the device has none)
    native_usb: bool = False  # a native-USB board: open it with DTR high

    @property
    def likely(self) -> bool:
        """A USB device of a kind that sensor boards carry."""
        return bool(self.bridge)


def usb_kind(vid: int | None, pid: int | None) -> UsbKind | None:
    """The known board kind of a USB vendor/product id, or None."""
    if vid is None:
        return None
    return KNOWN_BOARDS.get((vid, pid)) or KNOWN_BOARDS.get((vid, None))


def bridge_name(vid: int | None, pid: int | None) -> str:
    """The known board kind's name for a USB vendor/product id, or ""."""
    kind = usb_kind(vid, pid)
    return kind.name if kind else ""


def list_ports(*, include_all: bool = False) -> list[PortInfo]:
    """Serial ports, likely sensor boards first; without ``include_all`` only USB ports are listed."""
    import_serial()  # a clear ImportError naming the extra when pyserial is missing
    from serial.tools import list_ports as lp

    return candidate_ports(lp.comports(), include_all=include_all)


def candidate_ports(comports: Iterable[Any], *, include_all: bool = False) -> list[PortInfo]:
    """``comports`` (pyserial's ``ListPortInfo``: ``device``, ``description``, ``hwid``, ``vid``, ``pid``,
    ``serial_number``) as PortInfo: the likely sensor boards (a known USB kind) first, then by device path;
    without ``include_all``, ports without a USB vendor id (built-in UARTs, Bluetooth) are left out."""
    ports = []
    for p in comports:
        if not include_all and p.vid is None:
            continue
        kind = usb_kind(p.vid, p.pid)
        ports.append(PortInfo(device=p.device, description=p.description or "", hwid=p.hwid or "",
                              bridge=kind.name if kind else "", serial_number=p.serial_number or "",
                              native_usb=bool(kind and kind.native_usb)))
    return sorted(ports, key=lambda p: (not p.likely, p.device))


def device_for_serial_number(serial_number: str) -> str:
    """The device path of the one connected USB port with this serial number.

    Raises:
        SensorDisconnectedError: none (the message lists the serial numbers that are connected) or several.
    """
    found = [p for p in list_ports() if p.serial_number == serial_number]
    if len(found) == 1:
        return found[0].device
    if not found:
        present = ", ".join(f"{p.serial_number} ({p.device})" for p in list_ports() if p.serial_number) or "none"
        raise SensorDisconnectedError(f"no USB serial port with serial number {serial_number!r} is connected "
                                      f"(connected serial numbers: {present}); is the board plugged in? "
                                      "`tactile-manip find-port` lists the ports")
    raise SensorDisconnectedError(f"{len(found)} ports have serial number {serial_number!r} "
                                  f"({', '.join(p.device for p in found)}); open one by --port instead")
