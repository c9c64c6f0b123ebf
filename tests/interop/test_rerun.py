"""Rerun: episodes to .rrd read back with rerun's own reader (every frame, exact values), and `view --rerun`."""

from __future__ import annotations

import math

import numpy as np
import pytest

rr = pytest.importorskip("rerun", reason="Rerun export needs rerun-sdk (extra 'viz')")

from tactile_manip.cli import main  # noqa: E402
from tactile_manip.interop.rerun_export import write_rrd  # noqa: E402
from tactile_manip.interop.rerun_log import ARROW_MM_PER_UT, JOINTS, taxel_origins_mm  # noqa: E402
from tactile_manip.interop.rerun_read import read_entity  # noqa: E402
from tactile_manip.interop.rerun_sink import grpc_url, viewer_command  # noqa: E402
from tactile_manip.interop.timeline import episode_starts_s  # noqa: E402
from tactile_manip.boards import load_board  # noqa: E402


def _frames(episodes):
    return [f for e in episodes for f in e.frames]


def test_every_field_frame_reads_back_exactly(tmp_path, episodes):
    out = tmp_path / "run.rrd"
    summary = write_rrd(episodes, out)
    assert summary["frames"] == 80 and summary["episodes"] == 2
    frames = _frames(episodes)
    field = read_entity(out, "tactile/mbts/field")
    assert list(field.times["frame"]) == list(range(80))
    vectors = np.array(field.components["Arrows3D:vectors"], dtype=np.float32)      # (80, 16, 3) mm
    np.testing.assert_array_equal(vectors / np.float32(ARROW_MM_PER_UT),
                                  np.stack([f.field_ut.reshape(16, 3) for f in frames]))
    origins, _ = taxel_origins_mm((4, 4), load_board("supermag-4x4"))
    np.testing.assert_array_equal(np.array(field.components["Arrows3D:origins"][7]), origins)
    bz = read_entity(out, "tactile/mbts/bz")
    np.testing.assert_array_equal(np.array([d[0]["buffer"] for d in bz.components["Tensor:data"]], np.float32),
                                  np.stack([f.field_ut[..., 2].reshape(-1) for f in frames]))
    assert bz.components["Tensor:data"][0][0]["shape"] == [4, 4]


def test_timelines_hold_the_sensor_clock_per_episode_and_across_the_export(tmp_path, episodes):
    out = tmp_path / "run.rrd"
    write_rrd(episodes, out)
    field = read_entity(out, "tactile/mbts/field")
    t = np.concatenate([[f.t_s for f in e.frames] for e in episodes])
    np.testing.assert_array_equal(field.times["episode_time"], np.round(t * 1e9).astype(np.int64))
    starts = episode_starts_s(episodes)
    assert starts[0] == 0.0 and starts[1] == pytest.approx(7.5, abs=1e-3)   # the hosts' gap is kept
    sensor = np.concatenate([s + np.array([f.t_s for f in e.frames]) for s, e in zip(starts, episodes)])
    np.testing.assert_allclose(field.seconds("sensor_time"), sensor, atol=1e-9)
    assert (np.diff(field.times["sensor_time"]) > 0).all()
    host = np.array([f.host_time_s for f in _frames(episodes)])
    np.testing.assert_allclose(field.seconds("host_time"), host, atol=1e-9)


def test_estimates_robot_and_depth_read_back_exactly(tmp_path, episodes):
    out = tmp_path / "run.rrd"
    write_rrd(episodes, out)
    frames = _frames(episodes)
    odd = [f for f in frames if math.isfinite(f.angle_rad)]
    angle = read_entity(out, "tactile/mbts/angle_deg")
    assert [v[0] for v in angle.components["Scalars:scalars"]] == [math.degrees(f.angle_rad) for f in odd]
    conf = read_entity(out, "tactile/mbts/confidence")
    assert [v[0] for v in conf.components["Scalars:scalars"]] == [f.confidence for f in odd]
    joints = read_entity(out, JOINTS)
    np.testing.assert_array_equal(np.array(joints.components["Scalars:scalars"]),
                                  np.stack([f.joints_rad for f in frames]))
    depth = read_entity(out, "tactile/mbts/depth")
    with_depth = [f for f in frames if f.depth_mm is not None]
    assert len(depth) == len(with_depth) == 8
    for buf, fmt, f in zip(depth.components["DepthImage:buffer"], depth.components["DepthImage:format"], with_depth):
        image = np.frombuffer(bytes(buf[0]), np.float32).reshape(fmt[0]["height"], fmt[0]["width"])
        np.testing.assert_array_equal(image, f.depth_mm)
    vbts = read_entity(out, "tactile/vbts/depth")
    assert len(vbts) == 4                                                         # the first episode only
    phase = read_entity(out, "trial/phase")
    texts = [t[0] for t in phase.components["TextLog:text"]]
    assert texts == ["grasp", "estimate", "turn", "release"] * 2


def test_refuses_nothing_to_export_and_mixed_sensors(tmp_path, episodes):
    with pytest.raises(ValueError, match="no episode has frames"):
        write_rrd([], tmp_path / "x.rrd")
    episodes[1].meta["sensor_name"] = "left"
    with pytest.raises(ValueError, match="share a sensor"):
        write_rrd(episodes, tmp_path / "x.rrd")


def test_viewer_and_server_listen_on_localhost_unless_asked():
    cmd = viewer_command(serve=True, bind="127.0.0.1", port=9999)
    assert cmd[cmd.index("--bind") + 1] == "127.0.0.1" and "--serve-grpc" in cmd
    assert "--serve-grpc" not in viewer_command(serve=False, bind="127.0.0.1", port=9999)
    assert grpc_url("0.0.0.0", 9876) == "rerun+http://127.0.0.1:9876/proxy"


def test_view_sim_rerun_save_holds_every_frame_of_five_seconds(tmp_path, capsys):
    out = tmp_path / "x.rrd"
    assert main(["view", "--sim", "--rerun", "--save", str(out), "--seconds", "5", "--baseline-frames", "25"]) == 0
    field = read_entity(out, "tactile/mbts/field")
    assert 600 <= len(field) <= 630                                              # 125 Hz for 5 s
    assert (np.diff(field.times["frame"]) == 1).all()                           # no frame skipped
    assert 0 < len(read_entity(out, "tactile/mbts/depth")) <= 52                # --estimate-hz 10
    assert len(read_entity(out, "tactile/mbts/confidence")) > 0
    assert main(["view", "--sim", "--rerun", "--save", str(out), "--seconds", "1"]) == 2   # exists: no --force
    assert "exists; pass --force" in capsys.readouterr().err


@pytest.mark.parametrize("argv, match", [
    (["--save", "x.rrd"], "--save needs --rerun"),
    (["--rerun", "--snapshot", "x.png"], "does not go with --rerun"),
    (["--rerun", "--save", "x.rrd", "--estimate-hz", "0"], "--estimate-hz"),
    (["--rerun", "--serve", "--rerun-port", "70000"], "--rerun-port"),
    (["--rerun", "--save", "x.rrd", "--model", "nope.onnx", "--seconds", "1"], "nope.onnx"),
])
def test_view_rerun_option_errors_are_one_line(tmp_path, capsys, argv, match):
    argv = [a.replace("x.", f"{tmp_path}/x.") for a in argv]
    assert main(["view", "--sim", *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0]
    assert not list(tmp_path.iterdir())


def test_trials_rerun_logs_every_frame_and_each_outcome(tmp_path, capsys):
    pytest.importorskip("roboticstoolbox", reason="simulated trials need roboticstoolbox-python (extra 'robot')")
    from pathlib import Path

    from tactile_manip.trials.log import read_trials

    scene = Path(__file__).resolve().parents[2] / "configs" / "scenes" / "reorient_sim.toml"
    out, rrd = tmp_path / "R", tmp_path / "t.rrd"
    assert main(["trials", "--config", str(scene), "--trials", "2", "--methods", "bilinear", "--out", str(out),
                 "--quiet", "--rerun", "--save", str(rrd)]) == 0
    records = read_trials(out / "trials.jsonl")
    field = read_entity(rrd, "tactile/mbts/field")
    assert len(field) > 10 and (np.diff(field.times["frame"]) == 1).all()      # every frame, none skipped
    lines = [t[0] for t in read_entity(rrd, "trial/episode").components["TextLog:text"]]
    assert len(lines) == 4 and lines[1].startswith(f"trial 0 (bilinear): {records[0].outcome}")
    angles = [v[0] for v in read_entity(rrd, "tactile/mbts/angle_deg").components["Scalars:scalars"]]
    assert angles == [math.degrees(r.estimated_angle_rad) for r in records if r.estimated_angle_rad is not None]
    assert len(read_entity(rrd, JOINTS)) >= 1


def test_trials_refused_before_a_trial_leaves_no_recording(tmp_path, capsys):
    pytest.importorskip("roboticstoolbox", reason="simulated trials need roboticstoolbox-python (extra 'robot')")
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "configs" / "scenes" / "reorient_sim.toml").read_text()
    scene = tmp_path / "scene.toml"
    scene.write_text(text.replace('"models/supermag.onnx"', '"no_such_model.onnx"'))
    assert main(["trials", "--config", str(scene), "--methods", "supermag", "--out", str(tmp_path / "R"),
                 "--rerun", "--save", str(tmp_path / "t.rrd")]) == 2
    assert "no_such_model" in capsys.readouterr().err and not (tmp_path / "t.rrd").exists()


def test_serve_listens_on_localhost_only_and_receives_the_stream():
    import socket

    from tactile_manip.interop.rerun_sink import open_live

    with socket.socket() as s:                                                # a free port
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    sink = open_live(serve=True, port=port)
    try:
        assert sink.process is not None and sink.process.poll() is None
        assert "--bind" in sink.process.args and sink.process.args[sink.process.args.index("--bind") + 1] == "127.0.0.1"
        with socket.create_connection(("127.0.0.1", port), timeout=2):
            pass
        for address in _outside_addresses():                                  # this host's other interfaces
            with pytest.raises(OSError):
                socket.create_connection((address, port), timeout=2).close()
        with pytest.raises(OSError, match="taken"):
            open_live(serve=True, port=port)
        rr.log("x", rr.Scalars(1.0), recording=sink.recording)
    finally:
        sink.close()
    assert sink.process.poll() is not None                                     # the server we started is stopped


def _outside_addresses() -> list[str]:
    """This host's IPv4 interface addresses other than loopback (Linux; none elsewhere)."""
    import fcntl
    import socket
    import struct

    found = set()
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for _, name in socket.if_nameindex():
            try:
                packed = fcntl.ioctl(s.fileno(), 0x8915, struct.pack("256s", name[:15].encode()))  # SIOCGIFADDR
            except OSError:
                continue
            found.add(socket.inet_ntoa(packed[20:24]))
    return sorted(a for a in found if not a.startswith("127."))
