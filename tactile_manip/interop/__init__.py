"""Carrying our data into other tools: LeRobot datasets, Rerun recordings, MCAP bags.

Every writer here reads :class:`~tactile_manip.interop.frames.Episode` lists and imports its library
(pyarrow/pandas, rerun-sdk, mcap) only inside the functions that need it, each behind its own extra.
"""
