"""Real ports: which USB boards need DTR high, opening a board by its USB serial number, the CLI's port options."""

from __future__ import annotations

import pytest
from checks import assert_one_line_error

from tactile_manip.cli import main
from tactile_manip.commands import serial_options
from tactile_manip.errors import SensorDisconnectedError
from tactile_manip.sensors import SerialSensor, SerialSensorConfig
from tactile_manip.sensors.ports import PortInfo, device_for_serial_number, usb_kind
from tactile_manip.wire import WIRE_FORMATS


def test_find_port_says_which_boards_need_dtr_high(monkeypatch, capsys):
    kind = usb_kind(0x239A, 0x801F)
    fake = [PortInfo("/dev/ttyACM0", "Trinket M0", "USB VID:PID=239A:801F SER=ABC123", kind.name, "ABC123",
                     kind.native_usb)]
    monkeypatch.setattr("tactile_manip.sensors.ports.list_ports", lambda include_all=False: fake)
    assert main(["find-port"]) == 0
    line = capsys.readouterr().out.splitlines()[1]
    assert "/dev/ttyACM0" in line and "--dtr high" in line and "SAMD21" in line and "SER=ABC123" in line


def test_known_usb_ids_tell_bridges_from_native_usb_boards():
    for vid, pid in ((0x10C4, 0xEA60), (0x1A86, 0x7523), (0x1A86, 0x55D4), (0x0403, 0x6001)):
        assert not usb_kind(vid, pid).native_usb
    for vid, pid in ((0x303A, 0x1001), (0x239A, 0x801F), (0x2886, 0x802F), (0x2341, 0x804D)):
        assert usb_kind(vid, pid).native_usb
    assert usb_kind(0x1234, 1) is None and usb_kind(None, None) is None


def test_a_board_is_found_by_its_serial_number(monkeypatch):
    fake = [PortInfo("/dev/ttyUSB0", "CP2102", "", "CP210x", "PAD-LEFT"),
            PortInfo("/dev/ttyUSB1", "CP2102", "", "CP210x", "PAD-RIGHT")]
    monkeypatch.setattr("tactile_manip.sensors.ports.list_ports", lambda include_all=False: fake)
    assert device_for_serial_number("PAD-RIGHT") == "/dev/ttyUSB1"
    with pytest.raises(SensorDisconnectedError, match=r"'PAD-MIDDLE'.*PAD-LEFT \(/dev/ttyUSB0\)"):
        device_for_serial_number("PAD-MIDDLE")
    # the driver resolves the number on every (re)open, and names the board by it
    sensor = SerialSensor(SerialSensorConfig(serial_number="PAD-LEFT"))
    assert sensor.source == "usb-serial:PAD-LEFT" and sensor._device() == "/dev/ttyUSB0"  # noqa: SLF001
    with pytest.raises(ValueError, match="exactly one of port"):
        SerialSensorConfig(port="/dev/ttyUSB0", serial_number="PAD-LEFT")


def test_check_port_fails_without_opening_where_connect_would_fail_for_certain(tmp_path, monkeypatch):
    pytest.importorskip("serial", reason="the serial sensor needs pyserial (the serial extra)")
    missing = tmp_path / "ttyUSB9"
    with pytest.raises(SensorDisconnectedError, match=rf"{missing} does not exist.*find-port"):
        SerialSensor(SerialSensorConfig(port=str(missing))).check_port()
    missing.write_bytes(b"")  # a path that exists passes (opening it is connect()'s business)
    SerialSensor(SerialSensorConfig(port=str(missing))).check_port()
    fake = [PortInfo("/dev/ttyUSB0", "CP2102", "", "CP210x", "PAD-LEFT")]
    monkeypatch.setattr("tactile_manip.sensors.ports.list_ports", lambda include_all=False: fake)
    with pytest.raises(SensorDisconnectedError, match="no USB serial port with serial number 'PAD-RIGHT'"):
        SerialSensor(SerialSensorConfig(serial_number="PAD-RIGHT")).check_port()


def test_the_cli_offers_every_wire_format_and_refuses_a_bad_layout(tmp_path, capsys):
    assert serial_options.WIRE_FORMATS == tuple(WIRE_FORMATS)
    assert main(["record", "--port", "/dev/null-x", "--layout", "hexagon", "--out", str(tmp_path / "r")]) == 2
    assert_one_line_error(capsys.readouterr().err, "record", "unknown board 'hexagon'; known boards: anyskin-5")


def test_dtr_and_rts_levels_reach_the_port(monkeypatch):
    opened = {}

    class FakeSerial:
        def open(self):
            opened.update(dtr=self.dtr, rts=self.rts, port=self.port, exclusive=self.exclusive)

    fake = type("serial", (), {"Serial": FakeSerial, "SerialException": OSError})
    for dtr, rts in ((False, False), (True, True), (True, False)):
        sensor = SerialSensor(SerialSensorConfig(port="/dev/ttyACM0", dtr=dtr, rts=rts))
        sensor._open_port(fake)  # noqa: SLF001 - the settings applied before open(), without a device
        assert opened == {"dtr": dtr, "rts": rts, "port": "/dev/ttyACM0", "exclusive": True}


def test_a_board_file_sets_the_wire_format_and_baud_unless_they_are_given():
    import argparse

    def config(*flags):
        p = argparse.ArgumentParser()
        source = p.add_mutually_exclusive_group()
        source.add_argument("--port")
        serial_options.add_serial_options(p, source)
        return serial_options.serial_config(p.parse_args(["--port", "/dev/x", *flags]))

    assert (config().wire_format, config().baudrate) == ("supermag", 921600)   # the SuperMag firmware's
    eflesh = config("--board", "eflesh")
    assert (eflesh.wire_format, eflesh.baudrate, eflesh.layout) == ("anyskin", 115200, "eflesh")
    assert config("--board", "generic:10").wire_format == "anyskin"
    assert config("--layout", "anyskin-5").baudrate == 115200
    given = config("--board", "eflesh", "--baud", "230400", "--wire-format", "anyskin")
    assert (given.wire_format, given.baudrate) == ("anyskin", 230400)
