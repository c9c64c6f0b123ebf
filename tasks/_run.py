"""Shared entry point of the trial-scene scripts in tasks/: run a scene file next to the script and report.

Like `tactile-manip trials`, each run gets a new folder (runs/trials/<scene>-<UTC time>) unless --out names
one, --resume continues the run in --out, and a refused run (a folder that holds another run, a bad scene)
is one line on stderr with exit status 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tactile_manip.errors import TactileManipError
from tactile_manip.trials.log import run_folder
from tactile_manip.trials.runner import run_trials
from tactile_manip.trials.scene import load_scene


def main(scene_file: str, description: str) -> None:
    here = Path(__file__).resolve().parent
    scene_path = here / scene_file
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--out", default=None, help="run folder (default: runs/trials/<scene>-<UTC time>)")
    parser.add_argument("--resume", action="store_true", help="continue a killed run in --out")
    args = parser.parse_args()
    try:
        scene = load_scene(scene_path)
        out = run_folder(scene.name, args.out, resume=args.resume)
        run_trials(scene, out, scene_path=scene_path, resume=args.resume)
    except (TactileManipError, ValueError) as exc:
        print(f"{Path(sys.argv[0]).name}: error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    print((out / "summary.md").read_text(), end="")
