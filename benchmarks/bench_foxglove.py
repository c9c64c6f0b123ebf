"""The Foxglove transport of ``tactile-manip serve``: what a pad's live topics cost, and whether a WebSocket client
in another process gets them all, at the board's 125 Hz.

Run from the repository root (extra ``foxglove``; the client needs ``websockets`` and mcap-ros2-support)::

    python -m benchmarks.bench_foxglove [--seconds 60] [--stall-s 10] [--stall-depth-hz 25] [--cores 1]

A simulated pad streams at 125 Hz (a press every 1.5 s) through :class:`TactilePublisher` with the default model
into a :class:`FoxgloveTransport`; the independent client of the tests (``tests/interop/ros2/foxglove_ws_client.py``:
websockets and mcap-ros2-support's decoder, its own process) subscribes to every topic. This process is pinned to
one core (``--cores`` to change), the client is not. Two runs:

1. **streaming**, ``--seconds``: per topic, messages published and received, stamps missing from what was
   received (gaps), and the received rate (arrival times at the client) against the source's; reading ->
   published (from the reading's arrival to its last message handed to the transport, the estimate included)
   p50 / p99; the transport's ``publish`` call per message, p50 / p99 / max.
2. **a stalled client**: the client reads 50 messages, then nothing for ``--stall-s``, while the depth image
   (160 kB) is published too, at ``--stall-depth-hz``, so that the SDK's queue for that client (1024 messages)
   overflows: the same timings meanwhile, and the slow-client events the SDK logged. The client's losses (gaps)
   are the SDK's drops (it counts none itself).

Each ``publish`` call is timed on the wall clock and in this thread's CPU time: on a busy machine the wall time
holds the waits for a core, the CPU time what publishing costs.

It measures; it asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from benchmarks._common import machine_info, publish  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_OUT = ROOT / "docs" / "results" / "benchmarks" / "foxglove.json"
CLIENT = ROOT / "tests" / "interop" / "ros2" / "foxglove_ws_client.py"
PRESS = "letter_r,t=0.2,force=10,yaw=20,rise=0.3,hold=0.5"


class _Timed:
    """A transport whose publishers record how long each ``publish`` call takes."""

    def __init__(self, transport, calls_s: list[float], cpu_s: list[float]) -> None:
        self.transport, self.calls_s, self.cpu_s, self.name = transport, calls_s, cpu_s, transport.name

    def advertise(self, topic, type_name, qos=None):
        inner, calls, cpu = self.transport.advertise(topic, type_name, qos), self.calls_s, self.cpu_s

        class Pub:
            @property
            def drops(self) -> int:
                return inner.drops

            def publish(self, cdr: bytes, stamp_ns: int, seq: int) -> None:
                c0, t0 = time.thread_time(), time.perf_counter()
                inner.publish(cdr, stamp_ns, seq)
                calls.append(time.perf_counter() - t0)
                cpu.append(time.thread_time() - c0)

        return Pub()

    def add_service(self, name, srv_type, handler) -> None:
        self.transport.add_service(name, srv_type, handler)


def _pin(cpus) -> None:
    """Every thread of this process (the SDK's and the sensor's included) onto ``cpus``."""
    for tid in os.listdir("/proc/self/task"):
        try:
            os.sched_setaffinity(int(tid), cpus)
        except OSError:  # a thread that ended meanwhile
            pass


def _pct(values_s: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(values_s) * 1e3, q)) if values_s else float("nan")


def run(seconds: float, stall_s: float, cores: int, depth_hz: float | None) -> dict[str, Any]:
    from tactile_manip.interop.ros2.foxglove_transport import FoxgloveTransport
    from tactile_manip.interop.ros2.publisher import TactilePublisher
    from tactile_manip.perception.tactile_estimator import TactileEstimator
    from tactile_manip.sensors import SimulatedSensor, parse_press

    est = TactileEstimator.load()
    calls_s: list[float] = []
    cpu_s: list[float] = []
    with tempfile.TemporaryDirectory() as tmp, FoxgloveTransport(port=0) as fox:
        pub = TactilePublisher(est, _Timed(fox, calls_s, cpu_s), namespace="/tactile", depth_hz=depth_hz)
        out = Path(tmp) / "got.json"
        extra = ["--stall-after", "50", "--stall-s", str(stall_s)] if stall_s else []
        client = subprocess.Popen([sys.executable, str(CLIENT), fox.url, "--out", str(out), "--seconds",
                                   str(seconds + 5), "--wait-topics", str(len(pub.topics)), *extra],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert client.stdout.readline().strip() == "subscribed", client.stderr.read()
        everywhere = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else set()
        if cores and everywhere:
            _pin(sorted(everywhere)[:cores])
        while not all(p.channel.has_sinks() for p in fox.publishers.values()):
            time.sleep(0.01)
        pub.latencies_s = []
        stamps: list[int] = []
        depth_stamps: list[int] = []
        with SimulatedSensor() as sensor:
            est.set_noise_floor(sensor.calibrate_baseline(125).noise_ut)
            sensor.play([parse_press(PRESS)], period_s=1.5)
            with sensor.subscribe() as frames:
                t0 = time.monotonic()
                while time.monotonic() - t0 < seconds:
                    for f in [frames.get(1.0), *frames.drain()]:
                        depth_before = pub.topics["depth"].seq if "depth" in pub.topics else 0
                        pub.estimate(f.reading)
                        stamps.append(pub.stamp_ns(f.reading.t_host_s))
                        if "depth" in pub.topics and pub.topics["depth"].seq > depth_before:
                            depth_stamps.append(stamps[-1])
                elapsed = time.monotonic() - t0
        slow_events = fox.slow_client_events
        client.communicate(timeout=seconds + 60)
        if cores and everywhere:
            _pin(everywhere)
        got = json.loads(out.read_text())
    topics = {}
    for topic, msgs in sorted(got["messages"].items()):
        if topic not in {t.name for t in pub.topics.values()}:
            continue
        times = [t for t, _, _ in msgs]
        arrival = np.array([a for _, _, a in msgs]) * 1e-9
        rate = (len(msgs) - 1) / (arrival[-1] - arrival[0]) if len(msgs) > 1 else float("nan")
        sent = depth_stamps if "depth" in pub.topics and topic == pub.topics["depth"].name else stamps
        topics[topic] = {"published": len(sent), "received": len(msgs),
                         "gaps": len(set(sent) - set(times)), "received_hz": rate}
    return {"seconds": elapsed, "stall_s": stall_s, "depth_hz": depth_hz, "readings": len(stamps),
            "source_hz": len(stamps) / elapsed,
            "topics": topics, "drops": pub.drops, "slow_client_events": slow_events,
            "reading_to_published_ms": {"p50": _pct(pub.latencies_s, 50), "p99": _pct(pub.latencies_s, 99)},
            "publish_call_ms": {"p50": _pct(calls_s, 50), "p99": _pct(calls_s, 99), "max": _pct(calls_s, 100)},
            "publish_call_cpu_ms": {"p50": _pct(cpu_s, 50), "p99": _pct(cpu_s, 99), "max": _pct(cpu_s, 100)}}


def markdown(report: dict[str, Any]) -> str:
    rows = [("| run | readings (source Hz) | per topic: received / published, gaps, received Hz | "
             "reading -> published p50 / p99 | publish call p50 / p99 / max, wall (CPU) | drops (ours) | "
             "slow-client events |"),
            "|---|---|---|---|---|---|---|"]
    for name, r in report["runs"].items():
        per = "; ".join(f"{t.rsplit('/', 1)[-1]} {v['received']}/{v['published']}, {v['gaps']}, "
                        f"{v['received_hz']:.1f}" for t, v in r["topics"].items())
        lat, call, cpu = r["reading_to_published_ms"], r["publish_call_ms"], r["publish_call_cpu_ms"]
        us = " / ".join(f"{call[k] * 1e3:.0f} ({cpu[k] * 1e3:.0f})" for k in ("p50", "p99", "max"))
        rows.append(f"| {name} | {r['readings']} ({r['source_hz']:.1f}) | {per} | {lat['p50']:.2f} / "
                    f"{lat['p99']:.2f} ms | {us} us | {r['drops']} | {r['slow_client_events']} |")
    m = report["machine"]
    rows.append(f"\n{m.get('cpu_model', '?')}, {report['cores']} core(s) for this process (0: unpinned), "
                f"load average {m['load_average'][0]:.1f} at the start")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=60.0, help="streaming time of each run, s (60)")
    p.add_argument("--stall-s", type=float, default=10.0, help="how long the stalled client reads nothing (10)")
    p.add_argument("--stall-depth-hz", type=float, default=25.0,
                   help="depth images per second in the stalled run, so that the client's queue overflows (25)")
    p.add_argument("--cores", type=int, default=1, help="cores this process is pinned to (1; 0: no pinning)")
    p.add_argument("--out", default=str(DEFAULT_OUT))
    args = p.parse_args(argv)
    machine = machine_info()  # the load average before this run adds its own
    runs = {"streaming": run(args.seconds, 0.0, args.cores, None)}
    if args.stall_s > 0:
        runs[f"stalled client, depth at {args.stall_depth_hz:g} Hz"] = run(
            min(args.seconds, args.stall_s + 5), args.stall_s, args.cores, args.stall_depth_hz)
    report = {"benchmark": "foxglove", "cores": args.cores, "machine": machine, "runs": runs}
    publish(report, args.out, markdown)
    return 0


if __name__ == "__main__":
    sys.exit(main())
