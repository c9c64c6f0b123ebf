"""``tactile-manip serve``: a sensor's readings and estimates as live ROS 2 topics, without a ROS installation.

Sources as ``view`` has them: ``--port`` (the board, or the emulator's pty), ``--sim`` (the simulated sensor
pressing ``--press`` in a loop) or ``--replay`` (a recording, looped); ``--pads N`` serves N of them from one
process (``/tactile/pad0`` ... ; simulated or replayed). Transports: Zenoh as ``rmw_zenoh`` lays it out
(``--transport zenoh``, the default: ROS 2 nodes with ``RMW_IMPLEMENTATION=rmw_zenoh_cpp`` see the topics), a
Foxglove WebSocket server (``foxglove``), or both. Both listen on 127.0.0.1; another ``--bind`` address needs
``--allow-remote``, and serve says where it listens. It runs for ``--seconds`` or until Ctrl-C or SIGTERM, and
however it ends, no listener outlives it (the transports live in this process: even SIGKILL closes them).
Topics, services and QoS: docs/ros2.md.
"""

from __future__ import annotations

import argparse
import math
import os
import time

from tactile_manip.commands.serial_options import (
    add_serial_options,
    check_sim_board,
    serial_config,
)

DEFAULT_SIM_PRESS = "letter_r,t=0.3,force=10,yaw=20,rise=0.4,hold=0.6"
TRANSPORTS = ("zenoh", "foxglove", "both")


def add_arguments(p: argparse.ArgumentParser) -> None:
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--port", help="serial port of the board (or the emulator's path)")
    src.add_argument("--sim", action="store_true", help="the simulated sensor, pressing --press in a loop")
    src.add_argument("--replay", metavar="FILE", help="a recording from `tactile-manip record` (looped)")
    p.add_argument("--press", action="append", default=[], metavar="SPEC",
                   help=f"with --sim: scripted press (repeatable; default {DEFAULT_SIM_PRESS!r})")
    p.add_argument("--pads", type=int, default=1, help="pads served from this process (--sim or --replay; default 1)")
    p.add_argument("--baseline-frames", type=int, default=125, help="frames averaged for the baseline (125)")
    p.add_argument("--no-baseline", action="store_true", help="publish raw fields as the field (no baseline)")
    p.add_argument("--seconds", type=float, default=None, help="stop after this long, s (default: at Ctrl-C)")
    add_serial_options(p, src)
    ros = p.add_argument_group("ROS 2")
    ros.add_argument("--namespace", default="/tactile", help="the topics' namespace (default /tactile)")
    ros.add_argument("--node", default="tactile_manip", help="the node name others see (default tactile_manip)")
    ros.add_argument("--domain-id", type=int, default=None,
                     help="ROS domain id (default: $ROS_DOMAIN_ID, else 0)")
    ros.add_argument("--model", default="supermag",
                     help="pose model: supermag (default), bilinear, bicubic, an .onnx file, or none")
    ros.add_argument("--contact-model", default="contact", help="contact model: contact (default), a file, or none")
    ros.add_argument("--depth-hz", type=float, default=None,
                     help="publish the depth image (sensor_msgs/Image) at this rate (default: no depth topic)")
    net = p.add_argument_group("transport")
    net.add_argument("--transport", choices=TRANSPORTS, default="zenoh",
                     help="zenoh (rmw_zenoh layout, default), foxglove (WebSocket), or both")
    net.add_argument("--bind", default="127.0.0.1", help="address the transports listen on (default 127.0.0.1)")
    net.add_argument("--allow-remote", action="store_true",
                     help="allow a --bind address beyond loopback (anyone on that network can read and call tare)")
    net.add_argument("--zenoh-port", type=int, default=7447, help="Zenoh listening port (default 7447)")
    net.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                     help="also connect to this Zenoh router, e.g. tcp/127.0.0.1:7447 where rmw_zenohd runs "
                          "(repeatable)")
    net.add_argument("--no-listen", action="store_true", help="Zenoh: do not listen, only --connect")
    net.add_argument("--foxglove-port", type=int, default=8765, help="Foxglove WebSocket port (default 8765)")


def check_options(args: argparse.Namespace) -> None:
    """Every option that can be judged before a device or a port is opened (ValueError naming it)."""
    from tactile_manip.interop.ros2.names import check_namespace, check_node_name
    from tactile_manip.interop.ros2.zenoh_transport import check_bind

    args.namespace = check_namespace(args.namespace)
    check_node_name(args.node)
    check_bind(args.bind, allow_remote=args.allow_remote)
    if args.seconds is not None and not (args.seconds > 0 and math.isfinite(args.seconds)):
        raise ValueError(f"--seconds: expected a positive duration, got {args.seconds}")
    if args.depth_hz is not None and not (args.depth_hz > 0 and math.isfinite(args.depth_hz)):
        raise ValueError(f"--depth-hz: expected a positive rate, got {args.depth_hz}")
    if not 1 <= args.pads <= 64:
        raise ValueError(f"--pads: expected 1..64, got {args.pads}")
    if args.pads > 1 and not (args.sim or args.replay is not None):
        raise ValueError("--pads N serves N simulated or replayed pads; a board on a port is one pad")
    for flag in ("zenoh_port", "foxglove_port"):
        if not 1 <= getattr(args, flag) <= 65535:
            raise ValueError(f"--{flag.replace('_', '-')}: expected a TCP port 1..65535, got {getattr(args, flag)}")
    if args.domain_id is None:
        env = os.environ.get("ROS_DOMAIN_ID", "").strip()
        if env and not env.isdigit():
            raise ValueError(f"ROS_DOMAIN_ID={env!r}: expected a number 0..232")
        args.domain_id = int(env) if env else 0
    if not 0 <= args.domain_id <= 232:
        raise ValueError(f"--domain-id: expected 0..232, got {args.domain_id}")
    if args.no_listen and not args.connect:
        raise ValueError("--no-listen needs --connect ENDPOINT (else nobody could reach the topics)")


def open_sensors(args: argparse.Namespace) -> list:
    from tactile_manip.checks import check_nonblank
    from tactile_manip.sensors import (
        ReplaySensor,
        ReplaySensorConfig,
        SerialSensor,
        SimulatedSensor,
    )
    from tactile_manip.sensors.config import SimulatedSensorConfig

    if args.sim:
        return [SimulatedSensor(SimulatedSensorConfig(seed=i)) for i in range(args.pads)]
    if args.replay is not None:
        path = check_nonblank("--replay", args.replay)
        return [ReplaySensor(ReplaySensorConfig(path=path, loop=True)) for _ in range(args.pads)]
    return [SerialSensor(serial_config(args))]


def open_transport(args: argparse.Namespace):
    """The transport(s) ``--transport`` names, listening where the options say; closed by the caller."""
    from tactile_manip.interop.ros2.transport import Tee

    opened = []
    try:
        if args.transport in ("zenoh", "both"):
            from tactile_manip.interop.ros2.zenoh_transport import ZenohTransport

            opened.append(ZenohTransport(namespace=args.namespace, node=args.node,
                                         bind=None if args.no_listen else args.bind, port=args.zenoh_port,
                                         connect=args.connect, allow_remote=args.allow_remote,
                                         domain_id=args.domain_id))
        if args.transport in ("foxglove", "both"):
            from tactile_manip.interop.ros2.foxglove_transport import FoxgloveTransport

            opened.append(FoxgloveTransport(host=args.bind, port=args.foxglove_port,
                                            allow_remote=args.allow_remote).start())
    except BaseException:
        for t in opened:
            t.close()
        raise
    return opened[0] if len(opened) == 1 else Tee(opened)


def take_baselines(sensors: list, estimator, frames: int) -> None:
    """Each sensor's baseline, all at once (a second of frames each); the estimator's noise floor is the first's."""
    from concurrent.futures import ThreadPoolExecutor

    from tactile_manip.errors import CalibrationError

    with ThreadPoolExecutor(max_workers=len(sensors)) as pool:
        try:
            baselines = list(pool.map(lambda s: s.calibrate_baseline(frames), sensors))
        except CalibrationError as e:
            raise CalibrationError(f"{e} (a source that starts under load: serve it with --no-baseline)") from e
    estimator.set_noise_floor(baselines[0].noise_ut)


def describe_transport(transport) -> str:
    parts = getattr(transport, "transports", [transport])
    return "; ".join(t.description() if hasattr(t, "description") else t.name for t in parts)


def run(args: argparse.Namespace) -> int:
    from tactile_manip.extras import require
    from tactile_manip.interop.ros2.publisher import TactilePublisher
    from tactile_manip.interop.ros2.serve import (
        Pad,
        Server,
        pad_namespaces,
        say,
        summary,
    )
    from tactile_manip.perception.tactile_estimator import TactileEstimator
    from tactile_manip.sensors import parse_press

    if args.port or args.serial_number:
        require("serial", "serving a serial port")
    if args.transport in ("zenoh", "both"):
        require("zenoh", "serving ROS 2 topics over Zenoh")
    if args.transport in ("foxglove", "both"):
        require("foxglove", "serving ROS 2 topics over a Foxglove WebSocket server")
    check_options(args)
    check_sim_board(args)
    presses = [parse_press(s) for s in args.press or [DEFAULT_SIM_PRESS]] if args.sim else []
    namespaces = pad_namespaces(args.namespace, args.pads)
    pose = None if args.model.lower() == "none" else args.model
    contact = None if args.contact_model.lower() == "none" else args.contact_model
    estimator = TactileEstimator.load(pose, contact)  # a bad model fails before anything listens
    if args.depth_hz is not None and getattr(getattr(estimator, "pose", None), "reconstructor", None) is None:
        raise ValueError(f"--depth-hz: --model {args.model} decodes no depth image; name a pose model "
                         "(supermag, bilinear, an .onnx file) or leave --depth-hz out")
    sensors = open_sensors(args)
    for s in sensors:
        estimator.check_layout(s.layout.name)
    connected = []
    transport = None
    try:
        for s in sensors:  # a missing recording or port fails before anything listens
            s.connect()
            connected.append(s)
        if not args.no_baseline:
            take_baselines(sensors, estimator, args.baseline_frames)
        for s in sensors:
            if presses:
                s.play(presses, period_s=max(p.end_s for p in presses) + 0.5)
        transport = open_transport(args)
        say(f"serve: {describe_transport(transport)}")
        if args.allow_remote and args.bind not in ("127.0.0.1", "::1", "localhost"):
            say(f"serve: listening on {args.bind}, beyond this machine: anyone who reaches it can read the topics "
                "and call tare")
        pads = [Pad(s, TactilePublisher(estimator, transport, namespace=ns, depth_hz=args.depth_hz))
                for s, ns in zip(sensors, namespaces)]
        server = Server(pads, estimator, transport)
        say(f"serve: {len(pads)} pad(s) under {args.namespace} as node {args.node} (domain {args.domain_id}); "
            + ("Ctrl-C stops" if args.seconds is None else f"for {args.seconds:g} s"))
        start = time.monotonic()
        try:
            server.run(seconds=args.seconds)
        finally:
            say(summary(server, describe_transport(transport), time.monotonic() - start))
    finally:
        if transport is not None:
            transport.close()
        for s in connected:
            s.disconnect()
    return 0
