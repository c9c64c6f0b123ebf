"""The speed-vs-error report (``tactile-manip bench``): every reconstruction method on the same readings.

- :mod:`~tactile_manip.bench.machine`: the machine and library versions a report was measured with;
- :mod:`~tactile_manip.bench.candidates`: what is measured (methods x runtimes), model files and int8 copies;
- :mod:`~tactile_manip.bench.timing`: latency of one reading, batch throughput, reading -> angle latency;
- :mod:`~tactile_manip.bench.accuracy`: the readings, image metrics (as ``tactile-manip evaluate``) and
  reorientation trials (as ``tactile-manip trials``);
- :mod:`~tactile_manip.bench.report`: the markdown table, JSON and the Pareto plot;
- :mod:`~tactile_manip.bench.suite`: settings and the run that ties them together.

Importing this package costs numpy only; onnxruntime is loaded with the first model and torch only for the
torch-eager reference (through :mod:`tactile_manip.learning.cvae.eager`).
"""
