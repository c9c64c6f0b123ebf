"""Live ROS 2 topics and services of the pad's estimates (``tactile-manip serve``): names, messages, type
hashes and the transports (zenoh as ``rmw_zenoh`` speaks it, Foxglove WebSocket). Importing this package
imports nothing beyond the standard library; each transport imports its library when it is built."""
