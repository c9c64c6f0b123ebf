"""``tactile-manip serve`` over Zenoh: reading -> published latency on one core, and 16 pads from one process
on two cores, each received by an independent subscriber in another process.

    python -m benchmarks.bench_serve                       # 20 s each part, the default model
    python -m benchmarks.bench_serve --seconds 60 --out /tmp/serve.json

- ``latency``: one simulated pad (the default press loop), the default estimator (``TactileEstimator.load()``:
  the shipped pose and contact models), this process pinned to one core, the subscriber
  (``tests/interop/ros2/zenoh_client.py``: plain zenoh and mcap-ros2-support) on another where there is one.
  Per reading: from its arrival (``t_host_s``) to ``publish`` returning in the reading loop (estimate, four
  messages encoded and queued), and to the last of its messages handed to zenoh by the send thread.
- ``load``: ``--pads`` simulated pads served by :class:`~tactile_manip.interop.ros2.serve.Server` (estimates of
  the frames that came batched), this process pinned to two cores; per pad the readings published per second,
  frames the loop could not take (its subscription overflowed), messages dropped unsent, and the gaps in the
  sequence numbers the subscriber received on every topic.

The machine's load is printed with the table: these are wall-clock times on a shared machine. It measures and
asserts nothing; the table goes to stdout and the JSON (default ``docs/results/benchmarks/serve.json``, with a
``.md`` beside it).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from benchmarks._common import machine_info, publish  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CLIENT = ROOT / "tests" / "interop" / "ros2" / "zenoh_client.py"
TYPES = ("std_msgs/Float32MultiArray", "tactile_manip_msgs/Angle", "tactile_manip_msgs/Contact",
         "diagnostic_msgs/DiagnosticArray", "std_srvs/Trigger_Response")
PRESS = "letter_r,t=0.3,force=10,yaw=20,rise=0.4,hold=0.6"


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _pin(cores: int) -> list[int]:
    """Pin this process (and the threads it starts from now on) to its first ``cores`` CPUs."""
    allowed = list(range(os.cpu_count() or 1))  # from all of them: a pinned parent's mask is inherited
    chosen = allowed[:cores]
    os.sched_setaffinity(0, chosen)
    return chosen


def _client(port: int, seconds: float, out: Path, defs: Path, avoid: list[int]) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, str(CLIENT), "--connect", f"tcp/127.0.0.1:{port}", "--defs", str(defs),
                             "--seconds", str(seconds), "--out", str(out), "--keep-values", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    others = sorted(set(range(os.cpu_count() or 1)) - set(avoid))
    if others:
        os.sched_setaffinity(proc.pid, others)
    if proc.stdout.readline().strip() != "ready":
        raise RuntimeError(f"the subscriber did not start: {proc.stderr.read()[-2000:]}")
    return proc


def _defs(folder: Path) -> Path:
    from tactile_manip.interop.ros_msgs import ros2msg_text

    path = folder / "defs.json"
    path.write_text(json.dumps({t.replace("/", "/msg/"): ros2msg_text(t) for t in TYPES}))
    return path


def _gaps(seqs: list[int]) -> int:
    """Sequence numbers missing between the first and the last received (and before the first, from 1)."""
    return 0 if not seqs else int(seqs[-1] - len(set(seqs)))


def _stats_ms(values_s: list[float]) -> dict[str, float]:
    a = np.asarray(values_s) * 1e3
    return {"p50": float(np.percentile(a, 50)), "p99": float(np.percentile(a, 99)), "max": float(a.max()),
            "n": len(a)}


def measure_latency(seconds: float, folder: Path) -> dict[str, Any]:
    from tactile_manip.interop.ros2.publisher import TactilePublisher, estimate_readings
    from tactile_manip.interop.ros2.zenoh_transport import ZenohTransport
    from tactile_manip.perception.tactile_estimator import TactileEstimator
    from tactile_manip.sensors import SimulatedSensor, parse_press

    cores = _pin(1)
    est = TactileEstimator.load()
    port = _free_port()
    sent: list[float] = []
    lock = threading.Lock()

    def on_sent(topic: str, t: float) -> None:
        if topic == "/tactile/contact":  # the last of a reading's messages
            with lock:
                sent.append(t)

    arrivals, queued, estimate_s, publish_s = [], [], [], []
    with ZenohTransport(namespace="/tactile", port=port, on_sent=on_sent) as zt:
        client = _client(port, seconds + 10, folder / "latency.json", _defs(folder), cores)  # past the warm-up
        time.sleep(1.0)
        pub = TactilePublisher(est, zt, namespace="/tactile")
        with SimulatedSensor() as sensor:
            est.set_noise_floor(sensor.calibrate_baseline(125).noise_ut)
            sensor.play([parse_press(PRESS)], period_s=2.2)
            warm_end = time.monotonic() + 2.2  # one press cycle estimated first: first runs of every path
            while time.monotonic() < warm_end:
                est.estimate(sensor.wait_new(1.0))
            with sensor.subscribe() as frames:
                end = time.monotonic() + seconds
                while time.monotonic() < end:
                    reading = frames.get(1.0).reading
                    t0 = time.monotonic()
                    e = estimate_readings(est, [reading])[0]
                    estimate_s.append(time.monotonic() - t0)
                    t1 = time.monotonic()
                    pub.publish(reading, e)
                    publish_s.append(time.monotonic() - t1)
                    queued.append(time.monotonic() - reading.t_host_s)
                    arrivals.append(reading.t_host_s)
                overflowed = frames.overflowed
        time.sleep(0.5)
        drops = pub.drops
    client.communicate(timeout=120)
    got = json.loads((folder / "latency.json").read_text())
    with lock:
        wire = [s - a for s, a in zip(sent, arrivals)]
    seqs = got["topics"].get("/tactile/contact", {}).get("seqs", [])
    return {"cores": cores, "readings": len(arrivals), "estimate_ms": _stats_ms(estimate_s),
            "publish_ms": _stats_ms(publish_s),
            "to_published_ms": _stats_ms(queued), "to_zenoh_ms": _stats_ms(wire), "drops": drops,
            "overflowed": overflowed, "received": len(seqs), "gaps": _gaps(seqs)}


def measure_load(pads: int, seconds: float, folder: Path) -> dict[str, Any]:
    from tactile_manip.interop.ros2.publisher import TactilePublisher
    from tactile_manip.interop.ros2.serve import Pad, Server, pad_namespaces
    from tactile_manip.interop.ros2.zenoh_transport import ZenohTransport
    from tactile_manip.perception.tactile_estimator import TactileEstimator
    from tactile_manip.sensors import SimulatedSensor, parse_press
    from tactile_manip.sensors.config import SimulatedSensorConfig

    cores = _pin(2)
    est = TactileEstimator.load()
    port = _free_port()
    sensors = [SimulatedSensor(SimulatedSensorConfig(seed=i)) for i in range(pads)]
    for s in sensors:
        s.connect()
    try:
        for s in sensors:
            s.set_baseline(s.expected_baseline_ut)  # no second of calibration per pad: the load is the point
            s.play([parse_press(PRESS)], period_s=2.2)
        with ZenohTransport(namespace="/tactile", port=port) as zt:
            client = _client(port, seconds + 6, folder / "load.json", _defs(folder), cores)
            time.sleep(1.0)
            served = [Pad(s, TactilePublisher(est, zt, namespace=ns)) for s, ns in
                      zip(sensors, pad_namespaces("/tactile", pads))]
            server = Server(served, est, zt)
            server.run(seconds=seconds)
            elapsed = time.monotonic() - server.streaming_since_s
            time.sleep(1.0)
            rows = [{"pad": p.namespace, "readings": p.publisher.readings, "rate_hz": p.publisher.readings / elapsed,
                     "overflowed": p.subscription.overflowed, "drops": p.publisher.drops,
                     "sensor_rate_hz": p.sensor.health().rate_hz} for p in served]
    finally:
        for s in sensors:
            s.disconnect()
    client.communicate(timeout=120)
    got = json.loads((folder / "load.json").read_text())["topics"]
    gaps = {t: _gaps(v["seqs"]) for t, v in got.items() if t != "/diagnostics"}
    for row in rows:
        mine = {t: g for t, g in gaps.items() if t.startswith(row["pad"] + "/")}
        row["topics_received"] = len(mine)
        row["gaps"] = sum(mine.values())
        row["received"] = min((len(got[t]["seqs"]) for t in mine), default=0)
    return {"cores": cores, "pads": pads, "seconds": elapsed, "rows": rows,
            "min_rate_hz": min(r["rate_hz"] for r in rows), "total_gaps": sum(r["gaps"] for r in rows),
            "total_drops": sum(r["drops"] for r in rows), "total_overflowed": sum(r["overflowed"] for r in rows)}


def markdown(report: dict[str, Any]) -> str:
    lat, load = report.get("latency"), report.get("load")
    m = report["machine"]
    lines = [f"machine: {m.get('cpu_model', '')}, {m.get('usable_cores', '?')} usable cores; load average "
             f"{report['load_average']} at start, {report.get('load_average_end', '?')} at the end", ""]
    if lat:
        lines += [f"reading -> published, one pad, default model, pinned to core(s) {lat['cores']}, "
                  f"{lat['readings']} readings:", "",
                  "| stage | p50 ms | p99 ms | max ms |", "|---|---|---|---|"]
        for key, name in (("estimate_ms", "estimate alone"), ("publish_ms", "publish alone (encode, queue)"),
                          ("to_published_ms", "reading -> publish returned"),
                          ("to_zenoh_ms", "reading -> last message handed to zenoh")):
            s = lat[key]
            lines.append(f"| {name} | {s['p50']:.2f} | {s['p99']:.2f} | {s['max']:.2f} |")
        lines += ["", f"subscriber: {lat['received']} of {lat['readings']} contact messages received, {lat['gaps']} gaps; "
                  f"{lat['drops']} dropped unsent; {lat['overflowed']} frames not taken", ""]
    if load:
        lines += [f"{load['pads']} pads from one process, pinned to cores {load['cores']}, {load['seconds']:.1f} s:",
                  "", "| pad | published / s | sensor Hz | frames not taken | dropped | topics received | gaps |",
                  "|---|---|---|---|---|---|---|"]
        for r in load["rows"]:
            lines.append(f"| {r['pad']} | {r['rate_hz']:.1f} | {r['sensor_rate_hz']:.1f} | {r['overflowed']} | "
                         f"{r['drops']} | {r['topics_received']} | {r['gaps']} |")
        lines += ["", f"slowest pad {load['min_rate_hz']:.1f} readings/s; gaps {load['total_gaps']}, dropped "
                  f"{load['total_drops']}, frames not taken {load['total_overflowed']}"]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="each part's duration, s (default 20)")
    parser.add_argument("--pads", type=int, default=16)
    parser.add_argument("--part", choices=("both", "latency", "load"), default="both")
    parser.add_argument("--out", default="docs/results/benchmarks/serve.json")
    args = parser.parse_args()
    report: dict[str, Any] = {"machine": machine_info(), "load_average": [round(x, 2) for x in os.getloadavg()],
                              "seconds": args.seconds}
    with tempfile.TemporaryDirectory() as tmp:
        if args.part in ("both", "latency"):
            report["latency"] = measure_latency(args.seconds, Path(tmp))
        if args.part in ("both", "load"):
            # in a process of its own: the latency part pinned this one to a single core
            if args.part == "both":
                done = subprocess.run([sys.executable, "-m", "benchmarks.bench_serve", "--part", "load", "--seconds",
                                       str(args.seconds), "--pads", str(args.pads), "--out", f"{tmp}/load.json"],
                                      cwd=ROOT, capture_output=True, text=True, timeout=args.seconds + 600)
                if done.returncode != 0:
                    raise RuntimeError(done.stderr[-3000:])
                report["load"] = json.loads(Path(f"{tmp}/load.json").read_text())["load"]
            else:
                report["load"] = measure_load(args.pads, args.seconds, Path(tmp))
    report["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    publish(report, args.out, markdown)
    Path(args.out).with_suffix(".md").write_text(markdown(report) + "\n")


if __name__ == "__main__":
    main()
