"""Live ROS 2 topics without a ROS installation: ``tactile-manip serve`` and :class:`TactilePublisher`.

The pad's readings and estimates go out, per reading, as ROS 2 messages (CDR, the definitions of
:mod:`tactile_manip.interop.ros_msgs`, shared with the MCAP export) over a transport: Zenoh as ``rmw_zenoh``
speaks it (extra ``ros2``), a Foxglove WebSocket server (extra ``foxglove``), or in memory for tests. This
package's ``__init__`` imports nothing heavy; each transport imports its library when it is opened.
"""
