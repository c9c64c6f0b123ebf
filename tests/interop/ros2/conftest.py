"""The message definitions an independent client of the live ROS 2 tests is given (``defs``)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from ros2_helpers import TYPES

from tactile_manip.interop.ros_msgs import ros2msg_text


@pytest.fixture
def defs(tmp_path) -> Path:
    """The ``ros2msg`` definitions of every type served, keyed by ROS 2 name, as a client is given them."""
    path = tmp_path / "defs.json"
    path.write_text(json.dumps({t.replace("/", "/msg/"): ros2msg_text(t) for t in TYPES}))
    return path
