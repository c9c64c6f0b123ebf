"""The simulated sensor and everything that drives the simulator from the sensors layer (the one part of
``tactile_manip.sensors`` that imports ``tactile_manip.sim``):

- :class:`SimulatedSensor` (``sensor``): readings produced in process from the paired-sensor simulator;
- ``contacts``: scripted presses and ramps (:class:`~tactile_manip.sensors.simulated.contacts.ContactTimeline`)
  that the simulated sensor and the firmware emulator play;
- ``emulator``: the firmware emulator, which writes a board's wire bytes from simulated presses to a
  pseudo-terminal (``tactile-manip emulate``).
"""

from tactile_manip.sensors.simulated.sensor import SimulatedSensor

__all__ = ["SimulatedSensor"]
