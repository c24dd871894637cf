"""Helpers shared by the tests: seeded random problems on every algebra and order fits."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

import isoflow as iso
from isoflow._failures import MemberFailures
from isoflow.algebras import Algebra

Array = NDArray[Any]

ALGEBRA_FACTORIES: dict[str, Callable[[], Algebra]] = {
    "so4": lambda: iso.algebras.so(4),
    "u3": lambda: iso.algebras.u(3),
    "su3": lambda: iso.algebras.su(3),
    "sym4": lambda: iso.algebras.sym(4),
    "herm3": lambda: iso.algebras.herm(3),
    "sp4": lambda: iso.algebras.sp(4),
    "sl2": lambda: iso.algebras.sl2(),
    "glR3": lambda: iso.algebras.gl(3),
    "glC3": lambda: iso.algebras.gl(3, complex=True),
}
#: Spaces that are their own normalizer (Lie algebras closed under the conjugate transpose).
LIE_KEYS = ("so4", "u3", "su3", "sp4", "sl2", "glR3", "glC3")

#: Every space of the conformance suite: the matrix algebras, the compact vector forms and
#: the semidirect products (pairs of fields).
SPACES: dict[str, Callable[[], Algebra]] = {
    **ALGEBRA_FACTORIES,
    "so3-vectors": lambda: iso.algebras.so3_vectors(3),
    "sl2-vectors": lambda: iso.algebras.sl2_vectors(2),
    "so3-pairs": lambda: iso.algebras.semidirect(iso.algebras.so(3)),
    "su3-pairs": lambda: iso.algebras.semidirect(iso.algebras.su(3)),
    "se3-vectors": iso.algebras.se3_vectors,
}


def loglog_slope(hs: Array, errors: Array) -> float:
    """Least-squares slope of ``log(error)`` against ``log(h)``."""
    return float(np.polyfit(np.log(np.asarray(hs)), np.log(np.asarray(errors)), 1)[0])


def _spd(dim: int, rng: np.random.Generator) -> Array:
    """Random SPD matrix with spectrum in about [0.5, 2.5]."""
    A = rng.standard_normal((dim, dim))
    return 0.5 * (A @ A.T / dim + np.eye(dim))


def hamiltonian_problem(
    alg: Algebra, seed: int = 0, nonlinear: bool = False
) -> iso.IsospectralProblem:
    r"""Lie–Poisson problem ``B = (grad H)^dagger`` on a Lie algebra, seeded.

    ``H = q/2`` (linear ``B``) or ``H = q/2 + q^2/8`` (nonlinear ``B``) with
    ``q = <W, S W>`` for a random SPD ``S`` in coordinates, so that level sets of ``H``
    are compact and the flow stays bounded even on non-compact algebras.
    """
    rng = np.random.default_rng(seed)
    S = _spd(alg.dim, rng)

    def q_and_grad(W: Array) -> tuple[Array, Array]:
        c = alg.to_coords(W)
        Sc = c @ S.T
        return np.einsum("...i,...i->...", c, Sc), alg.from_coords(Sc)

    def H(W: Array) -> Array:
        q, _ = q_and_grad(W)
        return 0.5 * q + (0.125 * q**2 if nonlinear else 0.0)

    def grad(W: Array) -> Array:
        q, g = q_and_grad(W)
        factor = (1.0 + 0.5 * q).reshape(q.shape + (1,) * alg.core_ndim)
        return g * factor if nonlinear else g

    return iso.IsospectralProblem.from_hamiltonian(
        alg, H, grad, name=f"{'nonlinear' if nonlinear else 'linear'} LP on {alg.name}"
    )


def generic_problem(alg: Algebra, seed: int = 0, nonlinear: bool = False) -> iso.IsospectralProblem:
    """A non-Hamiltonian ``B`` into the normalizer: ``Pi_N(A W A^T) + K``, plus ``Pi_N(W^2 A)``."""
    norm_alg = alg.normalizer
    rng = np.random.default_rng(seed)
    n = alg.shape[-1]
    A = rng.standard_normal((n, n)) / np.sqrt(n)
    K = norm_alg.random(rng, scale=0.3)

    def B(W: Array) -> Array:
        M = A @ W @ A.T
        if nonlinear:
            M = M + W @ W @ A + np.sin(W)
        if not norm_alg.is_complex:
            M = np.real(M)
        return norm_alg.project(M) + K

    return iso.IsospectralProblem(B=B, algebra=alg, name=f"generic B on {alg.name}")


def random_problem(key: str, seed: int = 0, nonlinear: bool = False) -> iso.IsospectralProblem:
    """Hamiltonian problem on Lie algebras, generic ``B`` on sym(n) / herm(n)."""
    alg = ALGEBRA_FACTORIES[key]()
    if key in LIE_KEYS:
        return hamiltonian_problem(alg, seed, nonlinear)
    return generic_problem(alg, seed, nonlinear)


def space_problem(key: str, seed: int = 0) -> iso.IsospectralProblem:
    """A nonlinear problem on any space of :data:`SPACES`: Lie–Poisson on the Lie algebras and
    the vector forms, a generic ``B`` on sym(n) / herm(n)."""
    if key in ALGEBRA_FACTORIES:
        return random_problem(key, seed, nonlinear=True)
    return hamiltonian_problem(SPACES[key](), seed, nonlinear=True)


def space_state(alg: Algebra, seed: int, norm: float = 0.8) -> Array:
    """A seeded element of norm ``norm`` (for the vector forms: ``norm`` per particle)."""
    W = alg.random(seed)
    if alg.shape[1:] == (3,) and not isinstance(alg, iso.algebras.MatrixAlgebra):
        return W * (norm / np.linalg.norm(W, axis=-1, keepdims=True))
    return W * (norm / float(alg.norm(W)))


def initial_state(alg: Algebra, seed: int, norm: float = 0.8) -> Array:
    """A seeded random element of Frobenius norm ``norm``."""
    W = alg.random(seed)
    return W * (norm / float(alg.norm(W)))


def eigenvalue_drift(ys: Array) -> float:
    """Largest change of the sorted eigenvalues of the states ``ys`` (``(steps, *batch, n, n)``)
    from the first, relative to the spectral radius (``i W`` is Hermitian on the skew spaces,
    ``W`` itself on the others)."""
    skew = np.allclose(np.conj(np.swapaxes(ys[0], -1, -2)), -ys[0])
    ev = np.sort(np.linalg.eigvalsh(1j * ys if skew else ys), axis=-1)
    return float(np.max(np.abs(ev - ev[0])) / np.max(np.abs(ev[0])))


def length_drift(ys: Array, y0: Array) -> float:
    """Largest change of any particle's length ``|w_i|`` over the states ``ys`` from ``y0``."""
    return float(np.max(np.abs(np.linalg.norm(ys, axis=-1) - np.linalg.norm(y0, axis=-1))))


class PlainMapSpins(iso.algebras.SpinVectors):
    """``(R^3, x)^N`` without its closed-form stage: IsoMP iterates the plain map ``G`` and
    its midpoint update keeps ``|w_i|`` only to the stage's residual (runs on NumPy)."""

    closed_form_stage = False  # type: ignore[assignment]


def plain_map(prob: iso.IsospectralProblem) -> iso.IsospectralProblem:
    """``prob`` on :class:`PlainMapSpins` (the NumPy path)."""
    N = prob.algebra.shape[0]
    return dataclasses.replace(prob, kernel=None, algebra=PlainMapSpins(N))


def check_cayley_keeps_lengths(
    prob: iso.IsospectralProblem, y0: Array, method: type, n_steps: int, n_short: int
) -> None:
    """The Cayley update of ``method`` (``IsoMP`` or ``StochasticIsoMP``) on a particle space,
    ``dt = 0.05``: at ``rtol = 1e-6`` every ``|w_i|`` stays to 1e-14 over ``n_steps`` steps,
    and so it does with the midpoint update after the closed-form stage, while the plain map's
    midpoint update moves them by more than 1e-10; at ``rtol = 1e-14`` it is the midpoint
    update (``solver=FixedPoint()``) to 1e-12 over ``n_short`` steps; the compiled finish equals
    the NumPy path's to 1e-12."""

    def cayley(rtol: float) -> Any:
        return method(update="cayley", solver=iso.FixedPoint(rtol=rtol))

    kw: dict[str, Any] = dict(dt=0.05, n_steps=n_steps, progress=False)
    loose = method(solver=iso.FixedPoint(rtol=1e-6))
    mid = iso.solve(prob, loose, y0, **kw)
    plain = iso.solve(plain_map(prob), loose, y0, **kw)
    cay = iso.solve(prob, cayley(1e-6), y0, **kw)
    assert "compiled" in cay.stats.runner and "Cayley update" in cay.stats.runner
    assert plain.stats.runner == "NumPy"
    assert length_drift(plain.ys, y0) > 1e-10
    assert length_drift(mid.ys, y0) < 1e-14
    assert length_drift(cay.ys, y0) < 1e-14
    short = dict(kw, n_steps=n_short)
    tight = iso.solve(prob, cayley(1e-14), y0, **short)
    midpoint = iso.solve(prob, method(solver=iso.FixedPoint()), y0, **short)
    assert np.max(np.abs(tight.ys - midpoint.ys)) <= 1e-12
    numpy_path = iso.solve(dataclasses.replace(prob, kernel=None), cayley(1e-8), y0, **short)
    fast = iso.solve(prob, cayley(1e-8), y0, **short)
    assert numpy_path.stats.runner == "NumPy"
    assert np.max(np.abs(fast.ys - numpy_path.ys)) <= 1e-12


def spectrum_backward_error(W0: Array, W1: Array) -> float:
    r"""Eigenvalue change of ``W1`` against ``W0``, each divided by its condition number.

    Eigenvalues are matched optimally; ``|lambda_i(W1) - lambda_i(W0)| / kappa_i`` with
    :math:`\kappa_i = \|x_i\| \|y_i\| / |y_i^H x_i|` is the size of the perturbation of
    ``W0`` that explains the change to first order (``kappa = 1`` for normal matrices), so a
    non-normal matrix is not blamed for LAPACK's conditioning.
    """
    from scipy.linalg import eig
    from scipy.optimize import linear_sum_assignment

    e0, vl, vr = eig(W0, left=True, right=True)
    kappa = np.linalg.norm(vl, axis=0) * np.linalg.norm(vr, axis=0)
    kappa /= np.abs(np.einsum("ij,ij->j", np.conj(vl), vr))
    e1 = np.linalg.eigvals(W1)
    cost = np.abs(e0[:, None] - e1[None, :])
    r, c = linear_sum_assignment(cost)
    return float(np.max(cost[r, c] / kappa[r]))


@dataclasses.dataclass
class RunResult:
    """What a runner produced: saved rows, final state, method state, counters, failures."""

    rows: Array
    y: Array
    state: object
    k: int
    iterations: int
    iterations_max: int
    failures: MemberFailures
    label: str


def run_with(runner, n: int, save_every: int = 1, chunks: tuple[int, ...] | None = None,
             batch: tuple[int, ...] = ()) -> RunResult:  # fmt: skip
    """Advance ``runner`` by ``n`` steps (in the given chunk sizes), saving every ``save_every``."""
    from isoflow._save_grid import SaveGrid

    grid = SaveGrid(save_every, n)
    rows = []
    for c in chunks or (n,):
        out = np.empty(
            (grid.count(runner.k, runner.k + c), runner_members(runner), *runner_core(runner)),
            dtype=runner_dtype(runner),
        )
        k0 = runner.k
        runner.advance(c, grid, out)
        rows.append(out[: grid.count(k0, runner.k)])
    y, st = runner.state()
    return RunResult(
        rows=np.concatenate(rows), y=y, state=st, k=runner.k,
        iterations=runner.iterations_total, iterations_max=runner.iterations_max,
        failures=runner.failures, label=runner.label,
    )  # fmt: skip


def runner_members(r) -> int:
    return int(r.M)


def runner_core(r) -> tuple[int, ...]:
    return tuple(r.core)


def runner_dtype(r):
    return r.W.dtype if hasattr(r, "W") else r.Y.dtype


def compiled_and_numpy(problem, method, y, h, n, save_every=1, chunks=None):
    """The same run by the compiled runner and by the NumPy (method's own) runner."""
    from isoflow._compiled import compiled_runner
    from isoflow._stepping import PythonRunner

    cr = compiled_runner(problem, method, y, h)
    assert cr is not None, "no compiled path for this run"
    plain = dataclasses.replace(problem, kernel=None)
    pr = PythonRunner(plain, method, y, h)
    return run_with(cr, n, save_every, chunks), run_with(pr, n, save_every, chunks)


#: Agreement of a compiled run with the NumPy path, relative to ``max(1, max |y|)``.
FAST_TOL = 1e-13


def assert_same_run(a: RunResult, b: RunResult, iters_exact: bool = True) -> None:
    """A compiled run ``a`` equals the NumPy run ``b``: same steps, saved rows, final state and
    stored offsets to :data:`FAST_TOL`, same failures (members, steps, status, iterations) and
    iteration counts (exact, or within 1% when a residual may land on the tolerance)."""
    assert a.k == b.k
    scale = max(1.0, float(np.max(np.abs(b.rows))) if b.rows.size else 1.0)
    assert a.rows.shape == b.rows.shape
    if a.rows.size:
        assert np.max(np.abs(a.rows - b.rows)) <= FAST_TOL * scale
    assert np.max(np.abs(a.y - b.y)) <= FAST_TOL * scale
    if iters_exact:
        assert a.iterations == b.iterations
        assert a.iterations_max == b.iterations_max
    else:
        assert abs(a.iterations - b.iterations) <= max(2, b.iterations // 100)
    np.testing.assert_array_equal(a.failures.step, b.failures.step)
    np.testing.assert_array_equal(a.failures.status, b.failures.status)
    np.testing.assert_array_equal(a.failures.iterations, b.failures.iterations)
    if b.state is None:
        assert a.state is None
        return
    assert len(a.state) == len(b.state)
    alive = b.failures.alive
    for x, y in zip(a.state, b.state, strict=True):
        if not isinstance(y, np.ndarray):
            assert x == y  # step sizes, counts of a composition's layout
            continue
        assert x.shape == y.shape
        if x.ndim and x.shape[0] == alive.shape[0] and not alive.all():
            x, y = x[alive], y[alive]
        if x.size:
            assert np.max(np.abs(x - y)) <= FAST_TOL * scale


def _writes_to(path: Path, sf: Any) -> bool:
    """Whether the safe file ``sf`` is the published result file ``path``."""
    return path.exists() and os.path.samestat(os.fstat(sf.fileno()), path.stat())


def _disk(sf: Any) -> bytes:
    """The bytes of ``sf`` on disk now (what a SIGKILL before the next write leaves)."""
    fd = sf.fileno()
    return os.pread(fd, os.fstat(fd).st_size, 0)


@contextmanager
def disk_before_each_write(path: Path) -> Iterator[list[bytes]]:
    """Keep the bytes of the result file ``path`` before every write to it once it is published
    (the disk a SIGKILL at that write leaves), in the order of the writes."""
    from isoflow.io import safefile

    copies: list[bytes] = []

    def hook(sf: Any, offset: int, data: bytes) -> None:
        if _writes_to(path, sf):
            copies.append(_disk(sf))

    safefile.write_hook = hook
    try:
        yield copies
    finally:
        safefile.write_hook = None


@contextmanager
def disk_before_sampled_writes(
    path: Path, k: int, rng: np.random.Generator
) -> Iterator[dict[str, Any]]:
    """Keep the bytes of the result file ``path`` before ``k`` of its writes once it is
    published, drawn uniformly from all of them by reservoir sampling with ``rng``.

    How many writes a run makes depends on its chunk timing; draws fixed in advance would have
    to guess that number (a draw beyond it is a write that never comes). Yields
    ``{"writes": n, "copies": [bytes, ...]}`` (``n`` the writes seen, the copies in write order).
    """
    from isoflow.io import safefile

    kept: dict[int, tuple[int, bytes]] = {}  # reservoir slot -> (write number, bytes)
    out: dict[str, Any] = {"writes": 0, "copies": []}

    def hook(sf: Any, offset: int, data: bytes) -> None:
        if not _writes_to(path, sf):
            return
        out["writes"] += 1
        i = out["writes"]
        slot = len(kept) if len(kept) < k else int(rng.integers(0, i))
        if slot < k:
            kept[slot] = (i, _disk(sf))

    safefile.write_hook = hook
    try:
        yield out
    finally:
        safefile.write_hook = None
        out["copies"] = [b for _, b in sorted(kept.values())]


#: A user's model module: ``factory(n, seed)`` of a rigid body on so(n) with a Python ``B``.
USER_MODEL_SOURCE = '''
import numpy as np
import isoflow as iso


def factory(n=4, seed=0):
    """A rigid body on so(n) with a Python B (NumPy path)."""
    d = 1.0 + np.arange(n) / n
    C = 0.5 * (d[:, None] + d[None, :])

    def B(W):
        return {factor}C * W

    alg = iso.algebras.so(n)
    problem = iso.IsospectralProblem(B=B, algebra=alg, name="toy")
    return problem, alg.random(seed=seed, scale=0.5)
'''


def write_user_model(directory: Path, name: str, factor: str = "-", comment: str = "") -> None:
    """The user's module ``directory/name.py`` (:data:`USER_MODEL_SOURCE`) with
    ``B = {factor}C * W`` and a trailing ``comment``."""
    (directory / f"{name}.py").write_text(USER_MODEL_SOURCE.format(factor=factor) + comment)


def failed_ensemble_file(path: Any, n_steps: int = 30) -> Any:
    """``path`` holding a run of three so(4) rigid bodies whose member 1 fails at its first
    step (``h ||B||`` far above 2), streamed with ``throw=False``; returns ``path``."""
    from isoflow import io

    prob, _ = iso.models.rigid_body(4)
    Y = iso.algebras.so(4).random(seed=1, batch=(3,), scale=0.3)
    Y[1] *= 400.0
    iso.solve(prob, iso.IsoMP(), Y, dt=0.1, n_steps=n_steps, writer=io.HDF5Writer(path),
              throw=False, progress=False)  # fmt: skip
    return path
