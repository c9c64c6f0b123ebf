"""Behaviours: tactile skills composed from an arm, a gripper, a tactile sensor and an estimator
(:class:`~tactile_manip.perception.tactile_estimator.TactileEstimator`).

- :mod:`~tactile_manip.behaviours.reorient`: grasp, estimate the in-hand angle, turn the object to a target
  angle about the pad normal (the paper's experiment).
- :mod:`~tactile_manip.behaviours.place`: put a grasped rod into a slot at a commanded angle and position,
  correcting for the measured in-hand angle and contact offset.

A behaviour receives its hardware; it never builds it (docs/design.md, Layers).
"""
