"""One ensemble member whose ``B`` raises fails alone (issue 25): it is frozen at its last good
state with the code ``B raised`` (:mod:`isoflow._failures`) and the exception's text at the
step that raised; the others take every step, their states equal to a run without that member
bit for bit, on the compiled path (a user's ``CompiledB``, serial and parallel drivers) and on
the NumPy path (a vectorized ``B``)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import isoflow as iso
import user_kernels
from isoflow.threads import available_cores

N_STEPS, DT, BAD = 40, 0.05, 2
C = 0.5 * np.add.outer(np.arange(1.0, 5.0), np.arange(1.0, 5.0))
ALG = iso.algebras.so(4)


def _members() -> Any:
    """Four members; member :data:`BAD` much larger than the others."""
    Y = np.stack([ALG.random(s, scale=0.1) for s in range(4)])
    Y[BAD] = ALG.random(23, scale=0.8)  # its largest entry dips to 1.1, then rises to 1.65
    return Y


def _problem(limit: float, compiled: bool) -> iso.IsospectralProblem:
    if compiled:
        kernel = iso.CompiledB(user_kernels.raises_when_large, (C, float(limit)))
        return iso.IsospectralProblem(algebra=ALG, kernel=kernel)
    return iso.IsospectralProblem(B=user_kernels.raises_when_large_numpy(C, limit), algebra=ALG)


def _solve(Y: Any, limit: float, compiled: bool, **kw: Any) -> iso.Solution:
    return iso.solve(_problem(limit, compiled), iso.IsoMP(), Y, dt=DT, n_steps=N_STEPS,
                     progress=False, **kw)  # fmt: skip


def _limit_and_step(compiled: bool) -> tuple[float, int]:
    """A limit that member BAD's largest entry passes in the middle of the run (the others
    stay far below), and the step whose ``B`` raises: where the member alone raises, on its
    own NumPy run."""
    free = _solve(_members(), np.inf, compiled)
    a = np.abs(free.ys).max(axis=(2, 3))
    k = N_STEPS // 2
    assert np.all(np.diff(a[k - 5 : k + 2, BAD]) > 0) and a[: k + 1, BAD].max() == a[k, BAD]
    limit = a[k, BAD] + 0.25 * (a[k + 1, BAD] - a[k, BAD])
    assert np.delete(a, BAD, axis=1).max() < 0.5 * limit
    alone = _solve(_members()[BAD], limit, False, throw=False)
    assert k <= int(alone.failed_step) <= k + 2, alone.failed_step
    return float(limit), int(alone.failed_step)


#: The numba threads of each path: a solve sets numba's thread count from its own plan
#: (:mod:`isoflow.threads`), so the driver is chosen by ``threads=``, not by the caller's count.
NUMBA_THREADS = {"compiled, serial": 1, "compiled, parallel": 2, "NumPy": 1}


@pytest.fixture(params=list(NUMBA_THREADS))
def path(request: pytest.FixtureRequest) -> Any:
    if NUMBA_THREADS[request.param] > available_cores():
        pytest.skip("the parallel driver needs 2 cores")
    return request.param


def _threads(path: str) -> dict[str, int]:
    return {"blas": 1, "numba": NUMBA_THREADS[path]}


def test_only_the_member_whose_b_raises_fails(path: str) -> None:
    compiled = path != "NumPy"
    limit, k = _limit_and_step(compiled)
    Y = _members()
    sol = _solve(Y, limit, compiled, throw=False, threads=_threads(path))
    assert ("NumPy" in sol.stats.runner) != compiled, sol.stats.runner
    assert sol.stats.threads["numba"] == NUMBA_THREADS[path], sol.stats.threads
    assert not sol.success and sol.failed_step.tolist() == [-1, -1, k, -1]
    assert list(sol.failure_reasons) == [(BAD,)]
    assert sol.failure_reasons[(BAD,)] == "B raised: ValueError: entry too large"
    assert f"(2,) at step {k} (B raised: ValueError" in sol.message
    assert sol.message.endswith("The other members took every step.")  # no advice on dt

    others = np.delete(np.arange(4), BAD)
    alone = _solve(Y[others], limit, compiled, threads=_threads(path))  # without the bad one
    assert alone.success
    assert sol.ys[:, others].tobytes() == alone.ys.tobytes()
    free = _solve(Y, np.inf, compiled, threads=_threads(path))  # the bad one's good states
    assert sol.ys[: k + 1, BAD].tobytes() == free.ys[: k + 1, BAD].tobytes()
    assert all(row.tobytes() == sol.ys[k, BAD].tobytes() for row in sol.ys[k + 1 :, BAD])


def test_throw_raises_with_the_exception_as_cause(path: str) -> None:
    compiled = path != "NumPy"
    limit, k = _limit_and_step(compiled)
    with pytest.raises(iso.IsoflowError, match=f"at step {k}") as err:
        _solve(_members(), limit, compiled, threads=_threads(path))
    assert "\n" not in str(err.value)
    assert isinstance(err.value.__cause__, ValueError)
    assert str(err.value.__cause__) == "entry too large"


def test_a_field_declared_not_to_raise_ends_the_run_with_its_exception() -> None:
    """``CompiledB(..., raises=False)`` skips the per-call copy that lets a raising member be
    redone alone: a raise then ends the run with the field's own exception (serial driver);
    before it raises, the run equals the default one bit for bit."""
    limit, _ = _limit_and_step(True)
    Y = _members()
    kernel = iso.CompiledB(user_kernels.raises_when_large, (C, float(limit)), raises=False)
    prob = iso.IsospectralProblem(algebra=ALG, kernel=kernel)
    with pytest.raises(ValueError, match="entry too large"):
        iso.solve(prob, iso.IsoMP(), Y, dt=DT, n_steps=N_STEPS, progress=False,
                  threads={"blas": 1, "numba": 1})  # fmt: skip
    short = N_STEPS // 4  # far before the raise
    a = iso.solve(prob, iso.IsoMP(), Y, dt=DT, n_steps=short, progress=False)
    b = iso.solve(_problem(limit, True), iso.IsoMP(), Y, dt=DT, n_steps=short, progress=False)
    assert a.ys.tobytes() == b.ys.tobytes()


@pytest.mark.parametrize("value", [0, "no", None])
def test_compiled_b_raises_must_be_a_bool(value: Any) -> None:
    with pytest.raises(TypeError, match="raises must be True or False"):
        iso.CompiledB(user_kernels.raises_when_large, (C, 1.0), raises=value)


@pytest.mark.parametrize("compiled", [False, True], ids=["NumPy", "compiled"])
def test_a_member_whose_b_raises_at_its_initial_state_is_refused_by_name(compiled: bool) -> None:
    """The initial state is the input: the solve refuses it with a one-line InvalidBError that
    names the member and B's exception (not a broadcasting diagnosis), even with throw=False."""
    Y = _members()
    limit = 0.5 * float(np.abs(Y[BAD]).max())
    assert np.delete(np.abs(Y), BAD, axis=0).max() < limit  # only member BAD is over it
    with pytest.raises(iso.InvalidBError) as info:
        _solve(Y, limit, compiled, throw=False)
    message = str(info.value)
    assert f"at the initial state of member {BAD}" in message and "\n" not in message
    assert "last two axes" not in message
