"""Reorientation study: 300 presentations of six unseen rods, SuperMag vs bilinear on the same seeds.

Run: python tasks/reorient_study.py [--out DIR] [--resume]   (scene: tasks/reorient_study.toml)
"""

from _run import main

if __name__ == "__main__":
    main("reorient_study.toml", __doc__.splitlines()[0])
