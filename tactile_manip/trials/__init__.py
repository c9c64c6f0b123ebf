"""Reorientation trial runs: what is logged, how it is stored, scored and reported.

- ``record``: ``TrialRecord``, one trial as a flat JSON-serialisable record, and ``OUTCOMES``.
- ``log``: ``TrialLog``, the crash-safe ``RUN_DIR/trials.jsonl`` writer (with ``run.json``), ``read_trials``
  and ``completed_keys`` for resuming a killed run.
- ``stats``: Wilson intervals, exact McNemar, ``summarise`` (per method, paired, per object) and
  ``success_vs_tolerance`` (numpy/scipy only).
- ``report``: ``write_report``: ``summary.json``, ``summary.md`` and the figures (matplotlib, imported lazily).
- ``scene`` and ``runner``: the trial scene config and the runner behind ``tactile-manip trials``.

Importing this package imports none of its modules (no matplotlib, no robot stack); import what you use.
"""
