"""Read an MCAP export back with the ``mcap`` reader and our decoders, count the topics and plot what they hold.

Every message is decoded (CDR or JSON, whichever the file holds) with ``tactile_manip.interop``; no ROS
installation is needed. ``--plot`` draws Bz of the 16 taxels over time, the angle and confidence, and the
deepest depth image with the field of the same moment.

Run: python examples/read_mcap.py out/interop/press.mcap [--plot out/interop/press_mcap.png] [--name mbts]
"""

import argparse
import json
from collections import defaultdict

import numpy as np
from mcap.reader import make_reader

from tactile_manip.interop import cdr
from tactile_manip.interop.ros_msgs import MESSAGES, from_json


def read_topics(path: str) -> dict[str, list[tuple[float, dict]]]:
    """Topic -> [(log time in s, decoded message)] in file order."""
    out = defaultdict(list)
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            type_name = schema.name.replace("/msg/", "/")
            msg = (cdr.decode(MESSAGES, type_name, message.data) if channel.message_encoding == "cdr"
                   else from_json(type_name, json.loads(message.data)))
            out[channel.topic].append((message.log_time * 1e-9, msg))
    return dict(out)


def plot(topics: dict, name: str, path: str, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tactile_manip.plots import plot_depth, plot_field

    field = topics[f"/tactile/{name}/field"]
    t0 = field[0][0]
    t = np.array([s for s, _ in field]) - t0
    fields = np.stack([m["data"].reshape(-1, 3) for _, m in field])           # (N, taxels, 3) uT
    fig, ax = plt.subplots(2, 2, figsize=(11, 8), constrained_layout=True)
    ax[0, 0].plot(t, fields[..., 2], lw=0.8)
    ax[0, 0].set(xlabel="time (s)", ylabel="Bz (uT)", title=f"/tactile/{name}/field: Bz of each taxel")
    for topic, style, label in ((f"/tactile/{name}/angle", "o-", "angle (deg)"),):
        rows = topics.get(topic, [])
        ax[0, 1].plot([s - t0 for s, _ in rows], [np.degrees(m["data"]) for _, m in rows], style, ms=3, label=label)
    ax[0, 1].set(xlabel="time (s)", ylabel="angle (deg)", title=f"/tactile/{name}/angle and confidence")
    conf = topics.get(f"/tactile/{name}/confidence", [])
    twin = ax[0, 1].twinx()
    twin.plot([s - t0 for s, _ in conf], [m["data"] for _, m in conf], "s", color="tab:orange", ms=3)
    twin.set(ylabel="confidence", ylim=(0, 1.05))
    depth = topics.get(f"/tactile/{name}/depth", [])
    if depth:
        images = [np.frombuffer(m["data"], "<f4").reshape(m["height"], m["width"]) for _, m in depth]
        k = int(np.argmax([im.max() for im in images]))                     # the deepest contact
        s, image = depth[k][0], images[k]
        plot_depth(ax[1, 0], image, title=f"/tactile/{name}/depth at {s - t0:.2f} s (32FC1, mm)")
        i = int(np.argmin(np.abs(t - (s - t0))))
        plot_field(ax[1, 1], fields[i].reshape(4, 4, 3), title=f"the field at {t[i]:.2f} s (uT)")
    fig.suptitle(title)
    fig.savefig(path, dpi=90)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("mcap")
    p.add_argument("--plot", metavar="PNG")
    p.add_argument("--name", default="mbts", help="the sensor's name in the topics (default mbts)")
    args = p.parse_args()
    topics = read_topics(args.mcap)
    for topic, rows in topics.items():
        print(f"{topic}: {len(rows)} messages")
    if args.plot:
        plot(topics, args.name, args.plot, f"read back from {args.mcap} with the mcap reader")
        print(f"wrote {args.plot}")


if __name__ == "__main__":
    main()
