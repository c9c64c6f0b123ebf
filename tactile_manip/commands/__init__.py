"""One module per ``tactile-manip`` subcommand (``add_arguments(parser)`` and ``run(args) -> int``).

The checks on what a command writes (a folder it owns, a file it may replace) are in :mod:`tactile_manip.outputs`.
"""
