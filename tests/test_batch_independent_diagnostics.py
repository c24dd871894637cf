"""A state's diagnostics do not depend on the rows computed with it.

A run computes the diagnostics of the rows each chunk saves; after a kill, the resumed run
computes the same states in other batches (its first row alone). The sums over a matrix's
entries (energies, the distance to the space) give each member the same bits in any batch
(:mod:`isoflow._reductions`), so a resumed file's diagnostics equal the uninterrupted run's.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import isoflow as iso
from isoflow._reductions import real_inner, sum_of_squares
from isoflow.diagnostics import series


def _rows(alg: Any, count: int) -> Any:
    return alg.random(seed=4, batch=(count,), scale=0.3)


@pytest.mark.parametrize(
    "make",
    [
        lambda: iso.models.euler_sphere(N=128, seed=1)[0],  # einsum differed from N = 128
        lambda: iso.models.qg_sphere(N=128, seed=1)[0],
        lambda: iso.models.mhd_sphere(N=16, seed=1)[0],
        lambda: iso.models.rigid_body(6)[0],
    ],
    ids=["euler_sphere", "qg_sphere", "mhd_sphere", "rigid_body"],
)
def test_every_series_of_a_row_is_the_same_alone_and_in_a_batch(make: Any) -> None:
    problem = make()
    ys = _rows(problem.algebra, 23)
    together = series(problem, ys)
    for k in (0, 7, 22):
        alone = series(problem, ys[k : k + 1])
        for name, values in together.items():
            np.testing.assert_array_equal(alone[name][0], values[k], err_msg=name)


def test_the_sums_are_the_inner_products_and_bounded_in_memory() -> None:
    rng = np.random.default_rng(0)
    A = rng.standard_normal((5, 3, 7, 7)) + 1j * rng.standard_normal((5, 3, 7, 7))
    B = rng.standard_normal((5, 3, 7, 7)) + 1j * rng.standard_normal((5, 3, 7, 7))
    exact = np.einsum("...ab,...ab->...", np.conj(A), B).real
    np.testing.assert_allclose(real_inner(A, B), exact, rtol=1e-14)
    np.testing.assert_allclose(sum_of_squares(A.real), np.sum(A.real**2, axis=(-2, -1)))
    assert real_inner(A, B).shape == (5, 3)
