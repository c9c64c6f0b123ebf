"""The paper's experiment in simulation: three rods, two random orientations each, SuperMag vs bilinear.

Run: python tasks/paper_experiment.py [--out DIR] [--resume]   (scene: tasks/paper_experiment.toml)
"""

from _run import main

if __name__ == "__main__":
    main("paper_experiment.toml", __doc__.splitlines()[0])
