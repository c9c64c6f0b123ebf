"""One module per ``tactile-manip`` subcommand (``add_arguments(parser)`` and ``run(args) -> int``).

Shared here: :func:`check_report_folder`, the check every command that writes a folder of named files makes
before its work starts (defined in :mod:`tactile_manip.outputs`, so that the model kinds' verbs in
:mod:`tactile_manip.learning` use it too).
"""

from __future__ import annotations

from tactile_manip.outputs import check_report_folder

__all__ = ["check_report_folder"]
