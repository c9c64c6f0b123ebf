"""The interop modules import their libraries (rerun, mcap) only inside the functions that use them."""

from __future__ import annotations

import json
import subprocess
import sys


def test_importing_the_writers_and_the_view_pulls_in_no_viewer_or_bag_library():
    code = ("import sys, tactile_manip.interop.rerun_log, tactile_manip.interop.rerun_export, "
            "tactile_manip.interop.rerun_read, tactile_manip.interop.rerun_sink, tactile_manip.interop.rerun_view, "
            "tactile_manip.interop.mcap_export, tactile_manip.interop.cdr, tactile_manip.interop.ros_msgs, "
            "tactile_manip.commands.view, tactile_manip.commands.trials, "
            "tactile_manip.interop.ros2.type_hash, tactile_manip.interop.ros2.foxglove_transport, json\n"
            "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules} & "
            "{'rerun', 'rerun_bindings', 'mcap', 'mcap_ros2', 'pyarrow', 'pandas', 'onnxruntime', 'torch', "
            "'foxglove', 'websockets'})))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []
