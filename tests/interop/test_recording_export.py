"""A 10 s recording of the simulated sensor exported to .rrd and MCAP, each read back with its own library's
reader: every frame present, the field exact. The recording becomes an episode through the small reader
below (what a source reader does for the export command)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tactile_manip.cli import main
from tactile_manip.interop.frames import Episode, Frame
from tactile_manip.sensors import read_recording


def episode_from_recording(path) -> Episode:
    """Frames on the device clock's grid, the field less the mean of the first 25 frames (the free pad)."""
    rec = read_recording(path)
    raw = rec.field_raw_ut()
    field = (raw - raw[:25].mean(axis=0)).astype(np.float32)
    fps = 1.0 / float(np.median(np.diff(rec.t_device_s)))
    index = np.round((rec.t_device_s - rec.t_device_s[0]) * fps).astype(int)
    frames = [Frame(t_s=int(i) / fps, host_time_s=float(t), field_ut=f) for i, t, f in zip(index, rec.t_host_s, field)]
    return Episode(index=0, task="simulated presses", fps=fps, frames=frames,
                   meta={"layout": rec.layout_name})


@pytest.mark.slow
def test_a_ten_second_recording_exports_to_rrd_and_mcap_with_every_frame(tmp_path):
    pytest.importorskip("rerun", reason="needs rerun-sdk (extra 'viz')")
    mcap_reader = pytest.importorskip("mcap.reader", reason="needs mcap (extra 'mcap')")
    from tactile_manip.interop import cdr
    from tactile_manip.interop.mcap_export import write_mcap
    from tactile_manip.interop.rerun_export import write_rrd
    from tactile_manip.interop.rerun_log import ARROW_MM_PER_UT
    from tactile_manip.interop.rerun_read import read_entity
    from tactile_manip.interop.ros_msgs import MESSAGES

    path = tmp_path / "rec.tmrec"
    assert main(["record", "--sim", "--out", str(path), "--seconds", "10", "--quiet",
                 "--press", "hex_bar,t=1,force=10,yaw=30,size=4"]) == 0
    episode = episode_from_recording(path)
    n = len(episode.frames)
    assert 1200 <= n <= 1260 and math.isclose(episode.fps, 125.0, rel_tol=1e-6)
    fields = np.stack([f.field_ut for f in episode.frames])

    assert write_rrd([episode], tmp_path / "rec.rrd")["frames"] == n
    arrows = read_entity(tmp_path / "rec.rrd", "tactile/mbts/field")
    assert list(arrows.times["frame"]) == list(range(n))
    vectors = np.array(arrows.components["Arrows3D:vectors"], dtype=np.float32)
    np.testing.assert_array_equal(vectors / np.float32(ARROW_MM_PER_UT), fields.reshape(n, 16, 3))

    assert write_mcap([episode], tmp_path / "rec.mcap", ros2=True)["topics"] == {"/tactile/mbts/field": n}
    with open(tmp_path / "rec.mcap", "rb") as f:
        data = [cdr.decode(MESSAGES, "std_msgs/Float32MultiArray", m.data)["data"]
                for _, _, m in mcap_reader.make_reader(f).iter_messages(topics=["/tactile/mbts/field"])]
    np.testing.assert_array_equal(np.stack(data).reshape(n, 4, 4, 3), fields)
