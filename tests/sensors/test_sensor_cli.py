"""The sensor subcommands: emulate, record, find-port, view; and the import weight of the sensors package."""

from __future__ import annotations

import json
import subprocess
import sys
from types import SimpleNamespace

import pytest
from checks import assert_one_line_error

from tactile_manip.cli import COMMANDS, main
from tactile_manip.sensors import read_recording
from tactile_manip.sensors.ports import PortInfo, bridge_name, candidate_ports, list_ports

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def test_the_four_commands_are_registered():
    assert {"emulate", "record", "find-port", "view"} <= set(COMMANDS)


def test_sensor_modules_and_the_parser_stay_free_of_serial_and_matplotlib():
    code = ("import sys, tactile_manip, tactile_manip.sensors, tactile_manip.sensors.simulated.emulator, tactile_manip.cli\n"
            "tactile_manip.cli.build_parser()\n"
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'serial', 'matplotlib', 'torch'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_emulate_prints_the_path_first_and_a_report_last(capsys):
    assert main(["emulate", "--frames", "25", "--linger-s", "0", "--bit-flip-rate", "1"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].startswith("/dev/pts/")
    report = json.loads(lines[-1])
    assert report["event"] == "done" and report["frames_sent"] == 25 and report["corrupted_seqs"] == list(range(25))


@pytest.mark.parametrize("args, match", [
    (["--disconnect", "1:0.5"], "link"),
    (["--bit-flip-rate", "2"], "probability"),
    (["--press", "teapot"], "unknown object"),
    (["--linger-s", "-1"], "linger"),
])
def test_emulate_bad_options_are_one_line_errors(capsys, args, match):
    assert main(["emulate", *args]) == 2
    assert_one_line_error(capsys.readouterr().err, "emulate", match)


def test_record_the_simulated_sensor(tmp_path, capsys):
    out = tmp_path / "sim.tmrec"
    assert main(["record", "--sim", "--out", str(out), "--seconds", "1.0", "--press", "letter_r,t=0.2"]) == 0
    assert f"to {out}" in capsys.readouterr().out
    rec = read_recording(out)
    assert 100 <= len(rec) <= 135 and rec.header["backend"] == "SimulatedSensor"
    assert main(["record", "--sim", "--out", str(out), "--seconds", "1"]) == 2
    assert_one_line_error(capsys.readouterr().err, "record", "--force")
    assert main(["record", "--port", "/dev/null-x", "--out", str(tmp_path / "b"), "--press", "letter_r"]) == 2
    assert_one_line_error(capsys.readouterr().err, "record", "--sim")


@pytest.mark.parametrize("command", ["record", "view"])
def test_sim_with_another_board_is_refused_naming_the_emulator(tmp_path, capsys, command):
    out = tmp_path / "sim.tmrec"
    extra = ["--out", str(out)] if command == "record" else ["--snapshot", str(tmp_path / "v.png")]
    assert main([command, "--sim", "--board", "anyskin-5", "--seconds", "1", *extra]) == 2
    assert_one_line_error(capsys.readouterr().err, command, "--sim simulates the SuperMag board", "emulate --board")
    assert not out.exists() and not (tmp_path / "v.png").exists()


def test_record_a_missing_port_is_a_one_line_error(tmp_path, capsys):
    assert main(["record", "--port", str(tmp_path / "ttyUSB9"), "--out", str(tmp_path / "r.tmrec")]) == 2
    assert_one_line_error(capsys.readouterr().err, "record", "find-port")


def _comport(device: str, vid: int | None = None, pid: int | None = None, description: str = "",
             serial_number: str | None = None) -> SimpleNamespace:
    """What pyserial's comports() yields for one port (the fields list_ports reads)."""
    hwid = f"USB VID:PID={vid:04X}:{pid:04X}" if vid is not None else "n/a"
    return SimpleNamespace(device=device, vid=vid, pid=pid, description=description, hwid=hwid,
                           serial_number=serial_number)


# as the OS might list them: not in the order find-port shows them
COMPORTS = [_comport("/dev/ttyS0", description="ttyS0"),                                       # built-in UART
            _comport("/dev/ttyUSB1", 0x0403, 0x6001, "FT232R USB UART", "A10K"),                # FTDI bridge
            _comport("/dev/ttyACM0", 0x1234, 0x5678, "some USB modem"),                         # USB, unknown kind
            _comport("/dev/ttyUSB0", 0x10C4, 0xEA60, "CP2102 USB to UART Bridge Controller", "0001"),
            _comport("/dev/ttyACM3", 0x303A, 0x1001, "USB JTAG/serial debug unit")]             # Espressif USB


def test_candidate_ports_put_likely_boards_first_then_sort_by_device():
    ports = candidate_ports(COMPORTS)
    assert [p.device for p in ports] == ["/dev/ttyACM3", "/dev/ttyUSB0", "/dev/ttyUSB1", "/dev/ttyACM0"]
    assert [p.likely for p in ports] == [True, True, True, False]
    assert [p.native_usb for p in ports] == [True, False, False, False]
    assert ports[1].bridge.startswith("Silicon Labs CP210x") and ports[1].serial_number == "0001"
    assert ports[3].bridge == "" and ports[3].serial_number == ""
    assert candidate_ports(list(reversed(COMPORTS))) == ports  # the OS's order does not matter


def test_candidate_ports_leave_out_ports_without_usb_ids_unless_include_all():
    assert "/dev/ttyS0" not in [p.device for p in candidate_ports(COMPORTS)]
    every = candidate_ports(COMPORTS, include_all=True)
    assert [p.device for p in every] == ["/dev/ttyACM3", "/dev/ttyUSB0", "/dev/ttyUSB1", "/dev/ttyACM0", "/dev/ttyS0"]
    assert not every[-1].likely and every[-1].hwid == "n/a"
    assert candidate_ports([COMPORTS[0]]) == []


def test_find_port_prints_the_ports_in_list_ports_order(monkeypatch, capsys):
    pytest.importorskip("serial", reason="find-port needs pyserial (the serial extra)")
    import serial.tools.list_ports

    monkeypatch.setattr(serial.tools.list_ports, "comports", lambda: list(COMPORTS))
    assert main(["find-port"]) == 0
    rows = [line.split()[0] for line in capsys.readouterr().out.splitlines()[1:] if line.startswith("/dev/")]
    assert rows == ["/dev/ttyACM3", "/dev/ttyUSB0", "/dev/ttyUSB1", "/dev/ttyACM0"]
    assert main(["find-port", "--all"]) == 0
    out = capsys.readouterr().out
    assert "CP210x" in out and "Espressif" in out and out.index("/dev/ttyACM0") < out.index("/dev/ttyS0")
    monkeypatch.setattr(serial.tools.list_ports, "comports", lambda: [COMPORTS[0]])
    assert main(["find-port"]) == 1  # only a built-in UART: nothing to offer without --all
    assert "no USB serial port" in capsys.readouterr().err


def test_list_ports_runs_here():
    assert all(isinstance(p, PortInfo) for p in list_ports(include_all=True))
    assert bridge_name(0x1A86, 0x7523).startswith("WCH CH340") and bridge_name(0x1234, 1) == ""


def test_view_snapshot_of_the_simulated_sensor(tmp_path, capsys):
    out = tmp_path / "view.png"
    assert main(["view", "--sim", "--snapshot", str(out), "--seconds", "0.8", "--baseline-frames", "25"]) == 0
    assert "wrote" in capsys.readouterr().out
    data = out.read_bytes()
    assert data[:8] == PNG_MAGIC and len(data) > 10_000


def test_view_snapshot_of_the_emulator(emulator, tmp_path):
    e = emulator("--duration-s", "30", "--press", "allen_key,t=0.5,force=10", "--period-s", "2")
    out = tmp_path / "port.png"
    assert main(["view", "--port", e.path, "--snapshot", str(out), "--seconds", "0.6", "--no-baseline"]) == 0
    assert out.read_bytes()[:8] == PNG_MAGIC


def test_live_view_without_a_display_says_what_to_do(capsys, monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["view", "--sim"]) == 2
    assert_one_line_error(capsys.readouterr().err, "view", "--snapshot")


@pytest.mark.parametrize("argv", [
    ["record", "--port", "", "--out", "{tmp}/r.tmrec", "--seconds", "0.2"],
    ["record", "--port", "  ", "--out", "{tmp}/r.tmrec", "--seconds", "0.2"],
    ["view", "--port", "", "--snapshot", "{tmp}/v.png", "--seconds", "0.2"],
    ["view", "--replay", "", "--snapshot", "{tmp}/v.png", "--seconds", "0.2"],
    ["collect", "run", "--port", "", "--camera", "0", "--calibration", "{tmp}/c.npz", "--out", "{tmp}/d.npz"],
    ["collect", "calibrate", "--camera", "", "--corners", "0,0 1,0 1,1 0,1", "--ball-radius-mm", "3",
     "--out", "{tmp}/c.npz"],
])
def test_an_empty_port_or_path_is_an_error_not_the_simulated_sensor(argv, tmp_path, capsys):
    assert main([a.replace("{tmp}", str(tmp_path)) for a in argv]) == 2
    message = assert_one_line_error(capsys.readouterr().err, argv[0])
    assert "must not be empty" in message
    assert list(tmp_path.iterdir()) == []  # nothing recorded, nothing created


# ---------------------------------------------------------------- nothing overwritten, paths as written


def test_emulate_link_never_replaces_a_file_it_did_not_create(tmp_path, capsys):
    mine = tmp_path / "notes.txt"
    mine.write_text("my notes")
    assert main(["emulate", "--frames", "1", "--linger-s", "0", "--link", str(mine)]) == 2
    assert_one_line_error(capsys.readouterr().err, "emulate", "not an emulator's pty link")
    assert mine.read_text() == "my notes" and not mine.is_symlink()
    other = tmp_path / "other_link"
    other.symlink_to(mine)  # a link, but to the user's file, not to a pty
    assert main(["emulate", "--frames", "1", "--linger-s", "0", "--link", str(other)]) == 2
    assert other.is_symlink() and other.resolve() == mine


def test_emulate_replaces_a_stale_pty_link_and_removes_only_its_own(tmp_path, capsys):
    import os

    from tactile_manip.sensors.simulated.emulator import EmulatorConfig, FirmwareEmulator

    link = tmp_path / "board"
    link.symlink_to("/dev/pts/987654")  # left behind by a killed emulator
    with FirmwareEmulator(EmulatorConfig(link=str(link), frames=1)) as e:
        assert os.readlink(link) == e.device
        os.unlink(link)
        link.symlink_to("/dev/pts/987653")  # another emulator took the path meanwhile
    assert link.is_symlink() and os.readlink(link) == "/dev/pts/987653"  # not ours: left alone
    with FirmwareEmulator(EmulatorConfig(link=str(link), frames=1)):
        pass
    assert not os.path.lexists(link)  # ours: removed at close


def _recording(path, counts):
    from tactile_manip.sensors import RecordingWriter
    from tactile_manip.wire.protocol import encode_frame

    chip = {"lsb_xy_ut": 0.2, "lsb_z_ut": 0.323, "saturation_counts": 32767, "rate_hz": 125.0}
    with RecordingWriter(path, {"source": "test", "chip": chip}) as w:
        for i, c in enumerate(counts):
            w.write_frame(10.0 + i * 0.008, encode_frame(c, seq=i, t_mcu_us=8000 * i))
    return path


def test_view_a_recording_that_starts_under_load(tmp_path, capsys):
    import numpy as np

    rng = np.random.default_rng(0)
    free = rng.normal(0, 5, (150, 4, 4, 3)).astype(np.int16)
    load = free + np.linspace(0, 2000, 150).astype(np.int16)[:, None, None, None]  # pressed from the first frame
    _recording(tmp_path / "free.tmrec", free)
    _recording(tmp_path / "pressed.tmrec", load)
    assert main(["view", "--replay", str(tmp_path / "pressed.tmrec"), "--snapshot", str(tmp_path / "a"),
                 "--seconds", "0.2"]) == 2
    err = assert_one_line_error(capsys.readouterr().err, "view")
    assert "baseline refused" in err and "--baseline-from" in err and "--no-baseline" in err
    assert main(["view", "--replay", str(tmp_path / "pressed.tmrec"), "--snapshot", str(tmp_path / "a"),
                 "--seconds", "0.2", "--baseline-from", str(tmp_path / "free.tmrec")]) == 0
    assert f"wrote {tmp_path / 'a.png'} " in capsys.readouterr().out  # the file savefig wrote, .png added
    assert (tmp_path / "a.png").read_bytes()[:8] == PNG_MAGIC
    assert main(["view", "--replay", str(tmp_path / "pressed.tmrec"), "--snapshot", str(tmp_path / "a.png"),
                 "--seconds", "0.2", "--no-baseline"]) == 2
    assert_one_line_error(capsys.readouterr().err, "view", "exists; pass --force")


def test_view_replay_says_what_damage_it_skipped(tmp_path, capsys):
    import numpy as np

    path = _recording(tmp_path / "r.tmrec", np.zeros((40, 4, 4, 3), np.int16))
    data = bytearray(path.read_bytes())
    data[len(data) - 5 * 126 + 40] ^= 0x01  # one flipped bit in the fifth frame from the end
    path.write_bytes(bytes(data))
    assert main(["view", "--replay", str(path), "--snapshot", str(tmp_path / "v.png"), "--seconds", "0.2",
                 "--no-baseline"]) == 0
    err = capsys.readouterr().err
    assert "skipped 126 damaged bytes in 1 place(s); replaying the 39 intact frames" in err


def _emulate_on_link(link, *argv):
    import os
    import time

    proc = subprocess.Popen([sys.executable, "-m", "tactile_manip.cli", "emulate", "--link", str(link),
                             "--duration-s", "60", *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not os.path.islink(link) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    assert os.path.islink(link), proc.communicate(timeout=10)
    return proc


@pytest.mark.parametrize("sig, status", [("SIGTERM", 143), ("SIGINT", 130)])
def test_emulate_stopped_by_a_signal_exits_with_its_code_and_removes_its_link(sig, status, tmp_path):
    import os
    import signal

    link = tmp_path / "board"
    proc = _emulate_on_link(link)
    proc.send_signal(getattr(signal, sig))
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == status and f"emulate: stopped by {sig}" in err, err
    assert not os.path.lexists(link)


def test_emulate_killed_outright_leaves_no_link(tmp_path):
    """SIGKILL runs none of the command's cleanup: the watchdog it started removes the link."""
    import os
    import signal
    import time

    link = tmp_path / "board"
    proc = _emulate_on_link(link)
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=30)
    deadline = time.monotonic() + 10
    while os.path.lexists(link) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not os.path.lexists(link)


def test_record_stopped_by_sigterm_keeps_its_file_and_exits_143(tmp_path):
    import signal
    import time

    out = tmp_path / "r.tmrec"
    proc = subprocess.Popen([sys.executable, "-m", "tactile_manip.cli", "record", "--sim", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not (out.exists() and out.stat().st_size > 4096) and time.monotonic() < deadline:
        time.sleep(0.1)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 143 and "record: stopped by SIGTERM" in err, err
    assert len(read_recording(out).seq) > 0
