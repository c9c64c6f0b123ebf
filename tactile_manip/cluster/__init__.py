"""Running simulation and trials beyond one machine, on a Ray cluster (extra ``ray``).

Ray is imported only inside these modules' functions: ``tactile_manip.sim`` and ``tactile_manip.trials`` never
import it. Work is cut into blocks of per-sample seeds (or trial indices), so a distributed run gives exactly the
result of a local one.
"""
