"""Behaviours: the tasks trials run, each composed from an arm, a gripper, a tactile sensor and an estimator
(:class:`~tactile_manip.perception.tactile_estimator.TactileEstimator`).

- :mod:`~tactile_manip.behaviours.task`: what a task is (:class:`~tactile_manip.behaviours.task.Task`: its
  settings, one trial, the fields it logs, its report sections) and what it is handed per trial.
- :mod:`~tactile_manip.behaviours.registry`: the table of the tasks a scene can name.
- :mod:`~tactile_manip.behaviours.skills`: what tasks share: grasp, read the pad, move the hand, approach,
  release, and the trial-ending :class:`~tactile_manip.behaviours.skills.Abort`.
- :mod:`~tactile_manip.behaviours.reorient`: grasp, estimate the in-hand angle, turn the object to a target
  angle about the pad normal (the paper's experiment).
- :mod:`~tactile_manip.behaviours.place`: put a grasped rod into a slot at a commanded angle and position,
  correcting for the measured in-hand angle and contact offset.
- :mod:`~tactile_manip.behaviours.grip`: grip at a target force with the object centred, the contact state in
  the loop.

A behaviour receives its hardware; it never builds it (docs/design.md, Layers). A task of your own:
docs/your_task.md.
"""
