"""Units handed to numba threads as the threads come free.

numba's ``omp`` and ``workqueue`` layers split a ``prange`` statically, so the parallel driver
(:func:`isoflow._compiled.driver.drive_parallel`) runs a ``prange`` over its threads, each
taking the next unit from a shared counter (:func:`isoflow._compiled.atomics.take`):

* the counter is atomic: threads competing for two million indices take each exactly once;
* an ensemble whose members cost different numbers of iterations (sizes graded from the
  first member to the last, the case a static split handles worst) gives on two numba
  threads the states and records of one thread, bit for bit.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
import pytest

import isoflow as iso
from isoflow._compiled.atomics import take
from isoflow.threads import available_cores

two_cores = pytest.mark.skipif(
    available_cores() < 2 or numba.config.NUMBA_NUM_THREADS < 2, reason="needs 2 cores"
)


@numba.njit(parallel=True)
def _take_all(marks: Any, workers: int) -> None:
    counter = np.zeros(1, np.int64)
    for _ in numba.prange(workers):
        u = take(counter)
        while u < marks.shape[0]:
            marks[u] += 1
            u = take(counter)


@two_cores
def test_competing_threads_take_every_index_exactly_once() -> None:
    before = numba.get_num_threads()
    numba.set_num_threads(2)
    try:
        marks = np.zeros(2_000_000, np.int64)
        _take_all(marks, 2)
        _take_all(marks, 3)  # more takers than threads: the same
    finally:
        numba.set_num_threads(before)
    assert np.all(marks == 2)


def test_take_refuses_a_counter_of_another_type() -> None:
    @numba.njit
    def bad(c: Any) -> Any:
        return take(c)

    with pytest.raises(numba.TypingError):
        bad(np.zeros(1))


@two_cores
def test_members_of_different_cost_on_two_threads_equal_one_thread_bit_for_bit() -> None:
    M = 96
    alg = iso.algebras.so(10)
    prob, _ = iso.models.rigid_body(10)
    W = alg.random(seed=0, batch=(M,), scale=0.1) * np.linspace(0.2, 6.0, M)[:, None, None]
    runs = {
        t: iso.solve(prob, iso.IsoMP(), W, dt=0.1, n_steps=60, save_every=20, threads=t)
        for t in (1, 2)
    }
    assert runs[2].stats.threads["numba"] == 2 and runs[1].stats.threads["numba"] == 1
    per_member = [
        iso.solve(prob, iso.IsoMP(), W[m], dt=0.1, n_steps=60).stats.iterations_mean
        for m in (0, M - 1)
    ]
    assert per_member[1] > 1.5 * per_member[0]  # the members' costs differ
    assert np.array_equal(runs[1].ys, runs[2].ys)
    assert runs[1].stats.iterations_mean == runs[2].stats.iterations_mean
    assert runs[1].stats.iterations_max == runs[2].stats.iterations_max
