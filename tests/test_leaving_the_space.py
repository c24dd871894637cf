"""A ``B`` that leaves the normalizer fails the members whose flow leaves the space (issue 25):
``B`` at every saved state is checked (relative ``1e-8``), on the NumPy and the compiled path,
and such a member is frozen at its last saved state where ``B`` passed, with the code
``left the space`` (:mod:`isoflow._failures`), instead of a run reported ``completed`` with a
Casimir drift of order one.
(Every method projects its steps onto the space, so the states never show it: ``B`` does.)"""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import pytest

import isoflow as iso
import user_kernels
from isoflow._solve import RUN_FAILED
from isoflow._stepping import LEFT_SPACE_RTOL, PythonRunner, stop_members_leaving_the_space
from isoflow.io import HDF5Writer, load

ALG = iso.algebras.so(4)
C = 0.5 * np.add.outer(np.arange(1.0, 5.0), np.arange(1.0, 5.0))
DT, N_STEPS, SAVE, BAD = 0.05, 40, 4, 2


def _problem(limit: float, compiled: bool) -> iso.IsospectralProblem:
    if compiled:
        kernel = iso.CompiledB(user_kernels.leaves_when_large, (C, float(limit)))
        return iso.IsospectralProblem(algebra=ALG, kernel=kernel)
    return iso.IsospectralProblem(B=user_kernels.leaves_when_large_numpy(C, limit), algebra=ALG)


def _members() -> Any:
    """Three small members and member :data:`BAD`, whose largest entry rises from step 12."""
    Y = np.stack([ALG.random(s, scale=0.1) for s in range(4)])
    Y[BAD] = ALG.random(23, scale=0.8)
    return Y


def _solve(prob: iso.IsospectralProblem, Y: Any, **kw: Any) -> iso.Solution:
    return iso.solve(prob, iso.IsoMP(), Y, dt=DT, n_steps=N_STEPS, save_every=SAVE,
                     progress=False, **kw)  # fmt: skip


LIMIT = 1.4  # member BAD's largest entry passes it near step 26; the others stay below 0.3


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "NumPy"])
def test_one_system_that_leaves_the_space_fails(compiled: bool) -> None:
    y0 = _members()[BAD]
    sol = _solve(_problem(LIMIT, compiled), y0, throw=False)
    assert ("NumPy" in sol.stats.runner) != compiled
    assert not sol.success and sol.status == RUN_FAILED
    k = int(sol.failed_step)
    assert k % SAVE == 0 and N_STEPS // 2 <= k < N_STEPS, k  # its last saved state in so(4)
    reason = sol.failure_reasons[()]
    assert re.fullmatch(
        rf"left the space: B\(W\) after step {k + SAVE} is at distance \S+ from the normalizer "
        r"so\(4\) \(beyond \S+\), so the flow W' = \[B\(W\), W\] leaves so\(4\)",
        reason,
    ), reason
    assert sol.message == (
        f"IsoMP: {reason}; the run stops at the last saved state where B was in the "
        f"normalizer, after step {k} (t = {k * DT:g})"
    )
    assert sol.stats.n_steps == k and sol.ts[-1] == pytest.approx(k * DT)
    assert np.all(ALG.contains(sol.ys, rtol=LEFT_SPACE_RTOL))  # nothing off the space is kept
    assert float(np.max(sol.diagnostics.casimir_drift)) < 1e-12
    free = _solve(_problem(np.inf, compiled), y0)
    assert sol.ys.tobytes() == free.ys[: len(sol.ys)].tobytes()
    with pytest.raises(iso.NotInSpaceError, match=r"left the space: B\(W\) after step") as err:
        _solve(_problem(LIMIT, compiled), y0)
    assert err.value.distance > err.value.tolerance > 0


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "NumPy"])
def test_only_the_member_that_leaves_fails(compiled: bool) -> None:
    Y = _members()
    alone = _solve(_problem(LIMIT, compiled), Y[BAD], throw=False)
    sol = _solve(_problem(LIMIT, compiled), Y, throw=False)
    k = int(alone.failed_step)
    assert sol.failed_step.tolist() == [-1, -1, k, -1]
    assert sol.failure_reasons[(BAD,)] == alone.failure_reasons[()]
    others = [0, 1, 3]
    free = _solve(_problem(np.inf, compiled), Y)
    assert sol.ys[:, others].tobytes() == free.ys[:, others].tobytes()
    r = k // SAVE
    assert sol.ys[: r + 1, BAD].tobytes() == free.ys[: r + 1, BAD].tobytes()
    assert all(row.tobytes() == sol.ys[r, BAD].tobytes() for row in sol.ys[r + 1 :, BAD])


def test_a_file_holds_only_states_in_the_space(tmp_path: Any) -> None:
    path = tmp_path / "left.h5"
    sol = _solve(_problem(LIMIT, True), _members(), throw=False,
                 writer=HDF5Writer(path, chunk_rows=2, flush_seconds=0.0))  # fmt: skip
    data = load(path)
    assert data.run_info["status"] == RUN_FAILED and data.complete
    assert np.all(ALG.contains(data.ys, rtol=LEFT_SPACE_RTOL))
    assert int(sol.failed_step[BAD]) > 0


def test_a_member_whose_b_leaves_in_the_first_saved_row_goes_back_to_the_chunk_start() -> None:
    """Found at the first saved row of a chunk: frozen at the last state checked before it."""
    prob = _problem(0.5, False)  # B off so(4) for members with an entry beyond 0.5
    Y = _members()
    runner = PythonRunner(prob, iso.IsoMP(), Y, DT)
    before = 0.9 * Y  # the states the previous chunk ended with (checked)
    rows = np.stack([Y, Y])  # two saved rows, at steps 8 and 12
    last = stop_members_leaving_the_space(prob, runner, rows, np.array([8.0, 12.0]), (4, before))
    assert runner.failures.step.tolist() == [-1, -1, 4, -1]
    assert runner.failures.reason(BAD).startswith("left the space: B(W) after step 8 is at")
    assert all(r.tobytes() == before[BAD].tobytes() for r in rows[:, BAD])
    assert runner.state()[0][BAD].tobytes() == before[BAD].tobytes()
    assert last[0] == 12 and last[1].tobytes() == rows[-1].tobytes()


def test_long_runs_stay_far_below_the_tolerance() -> None:
    """Rounding does not come near it: 2e4 steps of a nonlinear field, saved every 2000."""
    prob = user_kernels.cubic_problem(ALG, seed=1, scale=0.5)
    sol = iso.solve(prob, iso.IsoMP(), ALG.random(1, scale=0.5), dt=DT, n_steps=20_000,
                    save_every=2000)  # fmt: skip
    assert sol.success
    assert float(np.max(sol.diagnostics.max_distance)) < 1e-6 * LEFT_SPACE_RTOL
