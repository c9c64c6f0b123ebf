"""Paired data collection for real sensors: cameras, the DTact depth pipeline and its calibration, force
sources, synchronised MBTS/VBTS pairing and pair logs.

It builds on :mod:`tactile_manip.sensors` (the magnetic sensor) and writes :mod:`tactile_manip.data` datasets;
``sensors`` never imports it. Modules:

- :mod:`~tactile_manip.collection.camera`: the ``Camera`` interface; :mod:`~.camera_opencv` (OpenCV, the
  ``camera`` extra) and :mod:`~.camera_sim` (the simulated DTact camera) behind it;
- :mod:`~.vbts`, :mod:`~.vbts_calibration`: the DTact depth pipeline and its ball calibration and alignment;
- :mod:`~.force`: force sources (the gripper's force threshold) that trigger a pair;
- :mod:`~.sync`: pairing depth frames with the nearest magnetic frame; :mod:`~.collect`, :mod:`~.collect_sim`:
  the recorder of a rig and its simulated twin; :mod:`~.pair_log`: crash-safe pair logs and the dataset
  made from them.

See ``docs/collection.md``.
"""
