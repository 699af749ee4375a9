"""splat's CPU threads follow the thread count the caller gives (snakemake's OMP_NUM_THREADS per job)."""
import os

import pytest

from splat.composite import _thread_budget


@pytest.mark.parametrize("given, expected", [("1", 1), ("3", 3), ("64", 16)])
def test_omp_num_threads_is_the_budget(monkeypatch, given, expected):
    monkeypatch.setenv("OMP_NUM_THREADS", given)
    assert _thread_budget() == expected


@pytest.mark.parametrize("given", [None, "", "0", "two"])
def test_without_a_usable_budget_every_cpu(monkeypatch, given):
    if given is None:
        monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    else:
        monkeypatch.setenv("OMP_NUM_THREADS", given)
    assert _thread_budget() == min(os.cpu_count() or 1, 16)
