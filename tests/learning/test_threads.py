"""A training run's thread limit holds numpy's BLAS as well as torch."""

from __future__ import annotations

import sys

import pytest

from tactile_manip.learning.threads import limited_threads


def _blas_threads(threadpoolctl) -> list[int]:
    return [p["num_threads"] for p in threadpoolctl.threadpool_info() if p["user_api"] == "blas"]


def test_the_blas_runs_on_the_given_threads_within_and_as_before_after() -> None:
    threadpoolctl = pytest.importorskip("threadpoolctl")
    before = _blas_threads(threadpoolctl)
    if not before:
        pytest.skip("numpy's BLAS is not one threadpoolctl can see")
    with limited_threads(1):
        assert _blas_threads(threadpoolctl) == [1] * len(before)
    assert _blas_threads(threadpoolctl) == before
    with limited_threads(0):   # 0: each library's default, untouched
        assert _blas_threads(threadpoolctl) == before


def test_without_threadpoolctl_it_says_what_to_install_and_still_runs(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "threadpoolctl", None)   # import threadpoolctl now raises ImportError
    ran = False
    with pytest.warns(RuntimeWarning, match="pip install threadpoolctl"), limited_threads(1):
        ran = True
    assert ran
