"""How many CPU threads a training run's numerical libraries use: torch's and numpy's BLAS alike.

A training config's ``threads`` bounds torch; numpy's BLAS (OpenBLAS in the numpy wheels) starts one thread per
core regardless, and its threads wait for work by spinning. Where anything else keeps a core busy (another job, or
torch itself), small least-squares and products on several spinning threads run several times slower than on
one: the few-label labeller's field-model passes on the eFlesh spatial run took 4-9 times the CPU time of one
thread with two on a shared two-core machine (about 1 s a refit on one, 4-9 s on two). :func:`limited_threads`
holds both to the config's count for the length of a run.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Iterator

NO_THREADPOOLCTL = ("numpy's BLAS may start a thread per core, which slows the labeller several times on a busy "
                    "machine: pip install threadpoolctl (it comes with the train extra) to hold it to `threads`")


@contextlib.contextmanager
def limited_threads(threads: int) -> Iterator[None]:
    """Within the block, torch (where it is imported) and numpy's BLAS use at most ``threads`` CPU threads each
    (0: each library's own default, nothing changed). The BLAS limit needs threadpoolctl; without it a warning
    says so and only torch is held."""
    if threads <= 0:
        yield
        return
    import sys

    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(threads)
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        warnings.warn(NO_THREADPOOLCTL, RuntimeWarning, stacklevel=3)
        yield
        return
    with threadpool_limits(limits=threads, user_api="blas"):
        yield
