"""Shared entry point of the trial-scene scripts in tasks/: run a scene file next to the script and report."""

from __future__ import annotations

import argparse
from pathlib import Path

from tactile_manip.trials.runner import run_trials
from tactile_manip.trials.scene import load_scene


def main(scene_file: str, description: str) -> None:
    here = Path(__file__).resolve().parent
    scene_path = here / scene_file
    scene = load_scene(scene_path)
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--out", default=f"runs/trials/{scene.name}", help="run folder")
    parser.add_argument("--resume", action="store_true", help="continue a killed run in --out")
    args = parser.parse_args()
    run_trials(scene, args.out, scene_path=scene_path, resume=args.resume)
    print((Path(args.out) / "summary.md").read_text(), end="")
