"""Reproducible increments and the stochastic isospectral midpoint (issue 22).

Statistical checks state their seeds and bounds: a bound of ``z`` standard errors fails a
correct implementation with probability below ``2 Phi(-z)`` (for ``z = 5``: 6e-7); the seeds are
fixed, so each check is deterministic.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import pytest
from scipy import stats
from scipy.special import ndtri

import isoflow as iso
from isoflow import noise
from isoflow._compiled.dense import dense_layout
from isoflow._compiled.spin_chain import PARALLEL_MIN_SPINS
from isoflow._compiled.stages import stage_for, stochastic_isomp
from isoflow._errors import InvalidBError, ParameterError, ShapeError
from isoflow.methods._base import StepDataRequest
from isoflow.noise import TransportNoise

# ---- the generator ------------------------------------------------------------------------------


def _reference_normals(seed: int, member: int, step: int, count: int, stream: int) -> np.ndarray:
    """The documented draws of one member's step, from numpy and scipy directly: the first
    ``count`` words of Philox with key ``(seed, stream)`` at counter ``member * b + 2**64 step``
    (``b = ceil(count / 4)`` blocks a member), as uniforms ``((w >> 12) + 1/2) 2**-52``, through
    ``ndtri``."""
    b = -(-count // 4)
    key = np.array([seed, stream], dtype=np.uint64)  # a list would go through float
    words = np.random.Philox(key=key, counter=member * b + (step << 64)).random_raw(4 * b)
    return ndtri(((words[:count] >> np.uint64(12)).astype(np.float64) + 0.5) * 2.0**-52)


@pytest.mark.parametrize(("seed", "count", "stream"), [(2**63 + 12345, 5, 0), (3, 8, 2)])
def test_normals_are_numpys_philox_words_through_ndtri_bit_for_bit(seed, count, stream) -> None:  # type: ignore[no-untyped-def]
    z = noise.standard_normals(seed, [0, 7, 3], 4, 3, count, stream=stream)
    for s in range(3):
        for j, m in enumerate((0, 7, 3)):
            ref = _reference_normals(seed, m, 5 + s, count, stream)
            assert z[s, j].tobytes() == ref.tobytes()


def test_extreme_raw_words_give_finite_normals() -> None:
    # the words 0 and 2**64 - 1 map to 2**-53 and 1 - 2**-53, never to 0 or 1 (with 53 bits
    # and + 1/2, the top word would round to 1 and give an infinite normal)
    raw = np.array([0, 2**64 - 1], dtype=np.uint64)
    out = np.empty(2)
    noise._normals_from_words(raw, out, None)
    assert np.all(np.isfinite(out)) and out[0] == -out[1] and 8.2 < out[1] < 8.21


def test_a_steps_normals_do_not_depend_on_the_chunks_or_the_other_members() -> None:
    whole = noise.standard_normals(11, [0, 1, 2, 3], 0, 12, 5)
    pieces = np.concatenate(
        [noise.standard_normals(11, [3, 1], k0, n, 5) for k0, n in ((0, 3), (3, 1), (4, 8))]
    )
    assert pieces[:, 0].tobytes() == whole[:, 3].tobytes()
    assert pieces[:, 1].tobytes() == whole[:, 1].tobytes()
    padded = noise.standard_normals(11, [2, -1], 0, 12, 5)
    assert padded[:, 0].tobytes() == whole[:, 2].tobytes() and not padded[:, 1].any()


def test_streams_seeds_and_members_draw_independent_normals() -> None:
    a = noise.standard_normals(1, [0], 0, 4, 4)
    assert not np.array_equal(a, noise.standard_normals(2, [0], 0, 4, 4))
    assert not np.array_equal(a, noise.standard_normals(1, [1], 0, 4, 4))
    assert not np.array_equal(a, noise.standard_normals(1, [0], 0, 4, 4, stream=1))


def test_normals_pass_a_kolmogorov_smirnov_test_against_the_standard_normal() -> None:
    # seed 99, 100 000 normals of 500 members (ids in two spans) over 40 steps: a correct
    # generator gives p < 1e-4 with probability 1e-4 (the seed fixes the outcome)
    ids = np.concatenate([np.arange(250), np.arange(10**6, 10**6 + 250)])
    z = noise.standard_normals(99, ids, 1000, 40, 5)
    assert stats.kstest(z.ravel(), "norm").pvalue > 1e-4


def test_normals_have_mean_zero_variance_one_and_no_step_correlation() -> None:
    # seed 2024, 200 000 normals: mean and variance within 5 standard errors
    z = noise.standard_normals(2024, np.arange(1000), 0, 40, 5)
    n = z.size
    assert abs(z.mean()) < 5 / math.sqrt(n)
    assert abs(z.var() - 1) < 5 * math.sqrt(2 / n)
    lag = float(np.mean(z[1:] * z[:-1]))  # consecutive steps of one member
    assert abs(lag) < 5 / math.sqrt(z[1:].size)


@pytest.mark.parametrize("method", [iso.StochasticIsoMP, iso.StochasticHeun])
def test_substeps_sum_the_increments_of_the_finer_steps(method) -> None:  # type: ignore[no-untyped-def]
    prob, _ = iso.models.rigid_body(3, noise=0.5, noise_seed=4)
    request = StepDataRequest(2, 3, np.array([1, -1, 0]), 0.4)  # steps 3..5 of h = 0.4
    coarse = method(substeps=4).step_data(prob, request)
    fine = noise.brownian_increments(4, [1, -1, 0], 8, 12, 3, 0.1)  # steps 9..20 of h = 0.1
    assert np.array_equal(coarse, fine.reshape(3, 4, 3, 3).sum(axis=1))
    assert not coarse[:, 1].any()


def test_truncated_increments_stay_within_the_level() -> None:
    h = 0.01
    A = noise.truncation_level(h)
    assert A == pytest.approx(math.sqrt(4 * math.log(100)))
    dW = noise.brownian_increments(5, np.arange(2000), 0, 50, 2, h)
    assert float(np.abs(dW).max()) <= A * math.sqrt(h) * (1 + 1e-15)
    free = noise.brownian_increments(5, np.arange(2000), 0, 50, 2, h, truncation=None)
    assert float(np.abs(free).max()) > A * math.sqrt(h)  # 200 000 draws reach beyond 4.3


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: noise.standard_normals(None, [0], 0, 1, 1), "seed is required"),
        (lambda: noise.standard_normals(-1, [0], 0, 1, 1), "seed must be in"),
        (lambda: noise.standard_normals(1.5, [0], 0, 1, 1), "seed must be an integer"),
        (lambda: noise.brownian_increments(1, [0], 0, 1, 1, 0.0), "step h must be positive"),
        (lambda: noise.brownian_increments(1, [0], 0, 1, 1, True), "step h must be positive"),
        (lambda: noise.truncation_level(0.0), "step h must be positive"),  # was math's error
        (lambda: noise.truncation_level(0.1, k=0.5), "truncation must be a number k >= 1"),
        (lambda: noise.brownian_increments(1, [0], 0, 1, 1, 0.1, truncation=0.5), "truncation"),
        (lambda: noise.standard_normals(1, [2**62], 0, 1, 16), "member id 4611686018427387904"),
    ],
)
def test_bad_noise_arguments_are_one_line_parameter_errors(call, message) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ParameterError, match=message) as info:
        call()
    assert "\n" not in str(info.value)


# ---- transport noise on a problem ---------------------------------------------------------------


def _rigid(n: int = 4, sigma: float = 0.3, seed: int = 3):  # type: ignore[no-untyped-def]
    prob, W0 = iso.models.rigid_body(n)
    F = sigma * np.stack([prob.algebra.random(i) for i in range(3)])
    return dataclasses.replace(prob, noise=TransportNoise(F, seed=seed)), W0


def test_bad_noise_on_a_problem_is_a_typed_one_line_error() -> None:
    prob, W0 = iso.models.rigid_body(4)
    with pytest.raises(ShapeError, match=r"fields must have shape \(m, 4, 4\)"):
        dataclasses.replace(prob, noise=TransportNoise(np.zeros((2, 3, 3)), seed=1))
    with pytest.raises(InvalidBError, match="not in the normalizer so"):
        dataclasses.replace(prob, noise=TransportNoise(np.ones((1, 4, 4)), seed=1))
    with pytest.raises(InvalidBError, match=r"site noise acts on \(R\^3, x\)\^N"):
        dataclasses.replace(prob, noise=TransportNoise(site=0.1, seed=1))
    with pytest.raises(ParameterError, match="seed is required"):
        TransportNoise(np.zeros((1, 4, 4)))
    good = 0.2 * np.stack([prob.algebra.random(i) for i in range(2)])
    for fields, error, message in [  # a fields function is checked at the initial state
        (lambda W: np.zeros((2, 3, 3)), ShapeError,
         r"the fields function must return shape \(2, 4, 4\) .* got \(2, 3, 3\)"),
        (lambda W: np.ones((2, 4, 4)), InvalidBError, "not in the normalizer so"),
        (lambda W: 1 / 0, InvalidBError, "the fields function raised ZeroDivisionError"),
        (lambda W: np.full((2, 4, 4), np.nan), InvalidBError, "non-finite"),
    ]:  # fmt: skip
        bad = dataclasses.replace(prob, noise=TransportNoise(fields, seed=1, count=2))
        with pytest.raises(error, match=message):
            iso.solve(bad, iso.StochasticIsoMP(), W0, dt=0.1, n_steps=1)
    fine = dataclasses.replace(prob, noise=TransportNoise(lambda W: good, seed=1, count=2))
    assert iso.solve(fine, iso.StochasticIsoMP(), W0, dt=0.1, n_steps=1).success
    with pytest.raises(ParameterError, match="rigid_body: noise_seed is required"):
        iso.models.rigid_body(3, noise=0.1)
    with pytest.raises(ParameterError, match="rigid_body: noise must be a finite number >= 0"):
        iso.models.rigid_body(3, noise=-0.1, noise_seed=1)
    noisy, _ = _rigid()
    with pytest.raises(ParameterError, match="IsoMP would ignore"):
        iso.solve(noisy, iso.IsoMP(), W0, dt=0.1, n_steps=1)
    with pytest.raises(  # the stochastic method with the same update
        ParameterError,
        match=r"with iso.StochasticIsoMP\(update='cayley'\) \(method 'stochastic-isomp-cayley'\)",
    ):
        iso.solve(noisy, iso.IsoMP(update="cayley"), W0, dt=0.1, n_steps=1)
    viscous, w0 = iso.models.euler_sphere(N=6, seed=1, noise=0.05, noise_seed=1, viscosity=0.01)
    with pytest.raises(  # the split step of IsoMP would drop the noise as IsoMP does
        ParameterError,
        match=r"Strang\(IsoMP\) would ignore: integrate it with iso.Strang\(iso.StochasticIsoMP",
    ):
        iso.solve(viscous, iso.Strang(), w0, dt=0.1, n_steps=1)
    with pytest.raises(ParameterError, match="symmetric"):
        iso.Composition(iso.StochasticIsoMP(), "suzuki-4")
    ids = dataclasses.replace(noisy, noise=noisy.noise.with_members([4, 5]))
    with pytest.raises(ShapeError, match="2 member ids for a run of 3 members"):
        iso.solve(ids, iso.StochasticIsoMP(), np.stack([W0] * 3), dt=0.1, n_steps=1)


_X3 = np.eye(3)


@pytest.mark.parametrize(
    ("call", "error", "message"),
    [
        (lambda: iso.models.rigid_body(3, noise=np.zeros((2, 4, 4)), noise_seed=1), ShapeError,
         r"fields must have shape \(m, 3, 3\) for so\(3\), got \(2, 4, 4\)"),
        (lambda: iso.models.rigid_body(3, noise=np.ones((3, 3)), noise_seed=1), ShapeError,
         r"fields must have shape \(m, 3, 3\)"),
        (lambda: iso.models.rigid_body(3, noise=np.ones((1, 3, 3)), noise_seed=1), InvalidBError,
         r"field 0 is not in the normalizer so\(3\)"),
        (lambda: iso.models.rigid_body(3, noise=1j * np.eye(3)[None], noise_seed=1),
         InvalidBError, "complex fields cannot act on the real space so"),
        (lambda: iso.models.euler_sphere(8, noise=np.ones((1, 8, 8)), noise_seed=1),
         InvalidBError, r"field 0 is not in the normalizer u\(8\)"),
        (lambda: iso.models.rigid_body(3, noise=[[["a"]]], noise_seed=1), ParameterError,
         "rigid_body: noise must be an amplitude or an array of fields"),
        (lambda: iso.models.rigid_body(3, noise=float("nan"), noise_seed=1), ParameterError,
         "rigid_body: noise must be a finite number >= 0, got nan"),
        (lambda: iso.models.sphere_vortices(_X3, [1, 1, 1], noise=-0.1, noise_seed=1),
         ParameterError, "sphere_vortices: noise must be a finite number >= 0"),
        (lambda: iso.models.sphere_vortices(_X3, [1, 1, 1], noise=0.1), ParameterError,
         "sphere_vortices: noise_seed is required"),
        (lambda: iso.models.euler_sphere(8, noise=0.1), ParameterError,
         "euler_sphere: noise_seed is required"),
        (lambda: iso.models.rigid_body(3, noise=0.1, noise_seed=-1), ParameterError,
         r"rigid_body: noise_seed must be in \[0, 2\*\*64\), got -1"),
        (lambda: TransportNoise(site=-1.0, seed=1), ParameterError,
         "site must be a number >= 0 or one per particle, got -1.0"),
        (lambda: iso.StochasticIsoMP(truncation=0), ParameterError,
         "truncation must be a number k >= 1 or None, got 0"),
        (lambda: iso.StochasticHeun(substeps=0), ParameterError,
         "substeps must be an integer >= 1, got 0"),
    ],
)  # fmt: skip
def test_bad_noise_input_of_the_models_is_a_one_line_typed_error(call, error, message) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(error, match=message) as info:
        call()
    assert type(info.value) is error and "\n" not in str(info.value)


def test_zero_noise_is_isomp_from_the_state_bit_for_bit() -> None:
    noisy, W0 = _rigid(sigma=0.0)
    prob = dataclasses.replace(noisy, noise=None)
    Y0 = np.stack([W0] * 3)
    kw = {"dt": 0.05, "n_steps": 40, "progress": False}
    a = iso.solve(noisy, iso.StochasticIsoMP(), Y0, **kw)
    b = iso.solve(prob, iso.IsoMP(initial_guess="state", compensated=False), Y0, **kw)
    c = iso.solve(prob, iso.StochasticIsoMP(), Y0, **kw)
    assert "compiled" in a.stats.runner
    assert a.ys.tobytes() == b.ys.tobytes() == c.ys.tobytes()


def test_the_split_step_of_stochastic_isomp_draws_each_steps_own_increments() -> None:
    """``Strang(StochasticIsoMP())`` is the half flows of the linear part around the
    stochastic step with the increments of that step and member (written out here from the
    method's documented pieces), and without a linear part the stochastic step itself bit for
    bit; drawing one step's increments at every step fails both."""
    prob, w0 = iso.models.euler_sphere(N=8, seed=1, noise=0.1, noise_seed=4, viscosity=0.02)
    Y0 = np.stack([w0, prob.algebra.project(1.1 * w0)])
    h, n = 0.05, 6
    split = iso.Strang(iso.StochasticIsoMP())
    sol = iso.solve(prob, split, Y0, dt=h, n_steps=n, progress=False)
    sto, lin = iso.StochasticIsoMP(), prob.linear_part
    for j in range(2):
        y = Y0[j]
        for k in range(n):
            dbeta = sto.step_data(prob, StepDataRequest(k, 1, np.array([j]), h))[0, 0]
            y = lin.flow(sto.step(prob, lin.flow(y, h / 2), h, data=dbeta).y, h / 2)
        assert np.max(np.abs(y - sol.ys[-1, j])) < 1e-13
    # no linear part, a noise field of the state (the NumPy path): the stochastic step exactly
    rigid, W0 = iso.models.rigid_body(4)
    fields = 0.3 * np.stack([rigid.algebra.random(i) for i in range(2)])
    noisy = dataclasses.replace(
        rigid, noise=TransportNoise(lambda W: np.broadcast_to(fields, (*W.shape[:-2], 2, 4, 4))
                                    * (1.0 + 0.1 * W[..., :1, 1:2, None]), seed=5, count=2)
    )  # fmt: skip
    a = iso.solve(noisy, iso.StochasticIsoMP(), W0, dt=0.05, n_steps=8, progress=False)
    b = iso.solve(noisy, split, W0, dt=0.05, n_steps=8, progress=False)
    assert a.stats.runner == b.stats.runner == "NumPy"
    assert a.ys.tobytes() == b.ys.tobytes()
    assert not np.array_equal(a.ys[1] - a.ys[0], a.ys[2] - a.ys[1])


def test_compiled_and_numpy_paths_take_the_same_noisy_steps_and_keep_the_casimirs() -> None:
    noisy, W0 = _rigid()
    Y0 = np.stack([W0 + 0.01 * k * noisy.algebra.random(k) for k in range(20)])  # lanes
    kw = {"dt": 0.01, "n_steps": 100, "progress": False}
    c = iso.solve(noisy, iso.StochasticIsoMP(), Y0, **kw)
    p = iso.solve(dataclasses.replace(noisy, kernel=None), iso.StochasticIsoMP(), Y0, **kw)
    assert "lanes" in c.stats.runner and p.stats.runner == "NumPy"
    assert float(np.abs(c.ys - p.ys).max()) < 1e-12
    assert float(np.abs(c.ys[-1] - Y0).max()) > 0.05  # the noise moved them
    assert float(np.max(c.diagnostics.casimir_drift)) < 1e-14
    single = iso.solve(noisy, iso.StochasticIsoMP(), Y0[0], **kw)  # member 0 alone, dense layout
    assert "lanes" not in single.stats.runner
    assert float(np.abs(single.ys - c.ys[:, 0]).max()) < 1e-13


def test_the_noise_term_formed_once_a_step_is_the_numpy_paths() -> None:
    # the rigid body's default noise on so(10): all 45 basis fields, summed once per solve
    # into a scratch row (the stage's begin) on the lanes and on one member's dense layout
    prob, W0 = iso.models.rigid_body(10, noise=0.3, noise_seed=2)
    assert prob.noise.count == 45
    Y0 = np.stack([W0 + 0.01 * k * prob.algebra.random(k) for k in range(18)])
    kw = {"dt": 0.02, "n_steps": 20, "progress": False}
    c = iso.solve(prob, iso.StochasticIsoMP(), Y0, **kw)
    one = iso.solve(prob, iso.StochasticIsoMP(), Y0[0], **kw)
    p = iso.solve(dataclasses.replace(prob, kernel=None), iso.StochasticIsoMP(), Y0, **kw)
    assert "lanes" in c.stats.runner and "compiled" in one.stats.runner
    assert p.stats.runner == "NumPy"
    assert float(np.abs(c.ys - p.ys).max()) < 1e-12
    assert float(np.abs(one.ys - p.ys[:, 0]).max()) < 1e-12
    assert float(np.abs(c.ys[-1] - Y0).max()) > 0.05


def test_member_ids_key_the_paths_whatever_the_ensemble_and_the_threads() -> None:
    noisy, W0 = _rigid(n=3)
    Y0 = np.stack([W0 * (1 + 0.1 * k) for k in range(4)])
    kw = {"dt": 0.02, "n_steps": 30, "progress": False}
    whole = iso.solve(noisy, iso.StochasticIsoMP(), Y0, threads={"numba": 2}, **kw)
    part = dataclasses.replace(noisy, noise=noisy.noise.with_members([2, 3]))
    tail = iso.solve(part, iso.StochasticIsoMP(), Y0[2:], threads={"numba": 1}, **kw)
    assert tail.ys.tobytes() == whole.ys[:, 2:].tobytes()
    again = iso.solve(noisy, iso.StochasticIsoMP(), Y0, threads={"numba": 1}, **kw)
    assert again.ys.tobytes() == whole.ys.tobytes()
    other = dataclasses.replace(noisy, noise=TransportNoise(noisy.noise.fields, seed=4))
    assert not np.array_equal(iso.solve(other, iso.StochasticIsoMP(), Y0, **kw).ys, whole.ys)


def test_ensemble_statistics_are_the_members_sample_moments_without_the_failed() -> None:
    noisy, W0 = _rigid(n=3)
    Y0 = np.stack([W0] * 6)
    sol = iso.solve(noisy, iso.StochasticIsoMP(), Y0, dt=0.05, n_steps=10, progress=False)
    est = iso.ensemble.ensemble_statistics(sol, noisy.hamiltonian)
    H = noisy.hamiltonian(sol.ys)  # (times, members)
    assert est.members == 6 and est.failed == 0 and est.mean.shape == (11,)
    assert np.allclose(est.mean, H.mean(axis=1), rtol=1e-14)
    assert np.allclose(est.standard_error, H.std(axis=1, ddof=1) / np.sqrt(6), rtol=1e-12)
    one = dataclasses.replace(sol, failed_step=np.array([-1, 3, -1, -1, -1, -1]))
    est = iso.ensemble.ensemble_statistics(one, noisy.hamiltonian)
    assert est.members == 5 and est.failed == 1
    assert np.allclose(est.mean, np.delete(H, 1, axis=1).mean(axis=1), rtol=1e-14)
    with pytest.raises(ParameterError, match="at least two members"):
        iso.ensemble.ensemble_statistics(iso.solve(noisy, iso.StochasticIsoMP(), W0, dt=0.05,
                                                   n_steps=2, progress=False))  # fmt: skip
    # complex states (herm(n)): a complex mean and the variance of |x - mean|^2, no part lost
    prob, B0 = iso.models.brockett(4)
    Z0 = np.stack([np.asarray(prob.algebra.project(s * np.asarray(B0))) for s in (0.8, 1.0, 1.3)])
    ens = iso.solve(prob, iso.IsoMP(), Z0, dt=0.05, n_steps=4, progress=False)
    est = iso.ensemble.ensemble_statistics(ens)
    Z = np.moveaxis(ens.ys, 1, 0)  # (members, times, 4, 4)
    assert est.mean.dtype.kind == "c" and np.abs(est.mean.imag).max() > 0.01
    assert np.array_equal(est.mean, Z.mean(axis=0))
    dev = np.abs(Z - Z.mean(axis=0)) ** 2
    assert np.allclose(est.variance, dev.sum(axis=0) / 2, rtol=1e-13, atol=0)


def test_the_registry_builds_the_noisy_models_from_their_parameters() -> None:
    make = iso.registry.MODELS
    prob, _ = make["euler-sphere"].make({"N": 8, "noise": 0.05, "noise_seed": 2})
    assert prob.noise.count == 8 and prob.noise.seed == 2
    prob, _ = make["rigid-body"].make({"n": 4, "noise": 0.1, "noise_seed": 3})
    assert prob.noise.count == 6 and prob.noise.seed == 3
    prob, _ = make["spin-lattice"].make({"shape": [3, 3], "temperature": 0.5, "damping": 0.2,
                                         "noise_seed": 4})  # fmt: skip
    assert prob.noise.site == pytest.approx(math.sqrt(2 * 0.2 * 0.5))


def test_stochastic_vortices_and_sphere_keep_their_casimirs_on_every_path() -> None:
    x0 = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])
    prob, x = iso.models.sphere_vortices(x0, [1.0, 2.0, -0.5], noise=0.3, noise_seed=1)
    sol = iso.solve(prob, iso.StochasticIsoMP(), np.stack([x] * 3), dt=0.01, n_steps=100,
                    progress=False)  # fmt: skip
    assert "point vortices" in sol.stats.runner
    assert float(np.max(sol.diagnostics.casimir_drift)) < 1e-14
    assert float(np.abs(sol.ys[-1] - sol.ys[0]).max()) > 0.05
    prob, Q = iso.models.euler_sphere(12, noise=0.05, noise_seed=2)
    assert prob.noise.count == 8  # the stream functions of degrees 1 and 2
    sol = iso.solve(prob, iso.StochasticIsoMP(), Q, dt=0.05, n_steps=20, progress=False)
    assert "compiled" in sol.stats.runner
    assert float(np.max(sol.diagnostics.casimir_drift)) < 1e-13


@pytest.mark.parametrize(
    ("make", "kind"),
    [
        (lambda: iso.models.rigid_body(20, noise=0.2, noise_seed=3), "dense so(20) (BLAS)"),
        (lambda: iso.models.euler_sphere(24, seed=1, noise=0.01, noise_seed=3), "(BLAS)"),
        (lambda: iso.models.euler_sphere(128, seed=1, noise=0.01, noise_seed=3), "real planes"),
    ],
    ids=["so-tiles", "su-tiles", "su-planes"],
)
def test_the_blas_iterations_with_noise_take_the_numpy_paths_steps(make, kind) -> None:  # type: ignore[no-untyped-def]
    # large dense states: the noise added to B before IsoMP's BLAS iteration (tiles, real
    # planes with 3M products) against the NumPy path, the same steps to rounding
    prob, W0 = make()
    h = 0.3 / float(np.linalg.norm(prob.B(W0), 2))
    kw = {"dt": h, "n_steps": 4, "progress": False}
    c = iso.solve(prob, iso.StochasticIsoMP(), W0, **kw)
    p = iso.solve(dataclasses.replace(prob, kernel=None), iso.StochasticIsoMP(), W0, **kw)
    assert kind in c.stats.runner and "stochastic IsoMP" in c.stats.runner
    assert p.stats.runner == "NumPy"
    on_blas = stage_for(iso.StochasticIsoMP()).on(dense_layout(prob, 1))
    assert on_blas is not None
    assert on_blas.iterate in (stochastic_isomp.iterate_tiles, stochastic_isomp.iterate_planar)
    scale = float(np.abs(W0).max())
    assert float(np.abs(c.ys - p.ys).max()) < 1e-12 * scale
    assert float(np.abs(c.ys[-1] - W0).max()) > 1e-3 * scale  # the steps moved the state
    assert float(np.max(c.diagnostics.casimir_drift)) < 1e-13


def _chain_noise(kind: str, N: int, seed: int) -> TransportNoise:
    """Noise on a chain of ``N`` spins: site noise, one constant field, or both."""
    field = np.zeros((1, N, 3))
    field[0, :, 2] = 0.2
    if kind == "site":
        return TransportNoise(seed=seed, site=0.3)
    if kind == "field":
        return TransportNoise(field, seed=seed)
    return TransportNoise(field, seed=seed, site=0.3)


def _noisy_chain(kind: str, N: int) -> tuple[iso.IsospectralProblem, np.ndarray]:
    """The Heisenberg chain with ``kind`` of noise; ``"thermal"``: the model at ``T = 0.5``
    with Gilbert damping 0.2 (the damped kernel)."""
    if kind == "thermal":
        return iso.models.heisenberg_chain(
            N, initial="random", seed=1, temperature=0.5, damping=0.2, noise_seed=2
        )
    prob, w0 = iso.models.heisenberg_chain(N, initial="random", seed=1)
    return dataclasses.replace(prob, noise=_chain_noise(kind, N, 2)), w0


def _on_the_generic_stage(prob: iso.IsospectralProblem) -> iso.IsospectralProblem:
    """The chain ``prob`` with its kernel's field as a ``CompiledB``: the generic particle
    stage instead of the chain's fused sweeps."""
    kernel = prob.kernel
    assert isinstance(kernel, iso.SpinNeighbourSum)
    return dataclasses.replace(prob, kernel=iso.CompiledB(*kernel.field(), name="chain field"))


@pytest.mark.parametrize("update", ["midpoint", "cayley"])
@pytest.mark.parametrize("kind", ["site", "field", "field and site", "thermal"])
def test_the_chains_fused_stochastic_sweep_takes_the_numpy_paths_steps(
    kind: str, update: str
) -> None:
    # the Heisenberg chain's fused sweeps (the (3, N) layout, the step's noise term formed once
    # a step by the stage's begin; the thermal chain's damped kernel) against the generic
    # particle stage (the same field as a CompiledB): the same states bit for bit; and against
    # the NumPy path to rounding, |S_i| kept
    prob, w0 = _noisy_chain(kind, 30)
    generic = _on_the_generic_stage(prob)
    kw = {"dt": 0.02, "n_steps": 50, "progress": False}
    method = iso.StochasticIsoMP(update=update, solver=iso.FixedPoint(rtol=1e-14))
    fused = iso.solve(prob, method, w0, **kw)
    particles = iso.solve(generic, method, w0, **kw)
    plain = iso.solve(dataclasses.replace(prob, kernel=None), method, w0, **kw)
    assert "spin chain" in fused.stats.runner and "(R^3, x)^N" in particles.stats.runner
    assert plain.stats.runner == "NumPy"
    assert np.array_equal(fused.ys, particles.ys)
    assert float(np.abs(fused.ys - plain.ys).max()) < 1e-12
    assert float(np.abs(fused.ys[-1] - w0).max()) > 0.05
    assert float(np.abs(np.linalg.norm(fused.ys, axis=-1) - 1).max()) < 1e-13


@pytest.mark.parametrize(
    "method",
    [iso.IsoMP(), iso.IsoMP(update="cayley"), iso.SphericalMidpoint()],
    ids=["IsoMP", "Cayley update", "spherical midpoint"],
)
def test_the_damped_chain_runs_on_the_fused_sweeps_as_on_the_generic_stage(method: Any) -> None:
    # Gilbert damping at T = 0 (the damped kernel on the chain's fused sweeps) against the generic
    # particle stage: the same states bit for bit; the damping raises the model's Lyapunov
    # function -H
    prob, w0 = iso.models.heisenberg_chain(30, initial="random", seed=4, damping=0.3)
    generic = _on_the_generic_stage(prob)
    kw = {"dt": 0.05, "n_steps": 60, "progress": False}
    fused = iso.solve(prob, method, w0, **kw)
    particles = iso.solve(generic, method, w0, **kw)
    assert "spin chain" in fused.stats.runner and "(R^3, x)^N" in particles.stats.runner
    assert np.array_equal(fused.ys, particles.ys)
    lyapunov = prob.lyapunov
    assert lyapunov is not None
    assert float(lyapunov(fused.ys[-1])) > float(lyapunov(w0)) + 0.1


@pytest.mark.parametrize("kind", ["site", "field and site", "thermal"])
def test_the_chains_threaded_stochastic_sweeps_equal_the_serial_ones(kind: str) -> None:
    # a chain long enough for threaded sweeps (numba threads over chunks, the noise term read
    # by every chunk) against the serial sweeps of threads=1: the same states to rounding
    noisy, w0 = _noisy_chain(kind, PARALLEL_MIN_SPINS)
    kw = {"dt": 0.05, "n_steps": 6, "save_every": 3, "progress": False}
    threaded = iso.solve(noisy, iso.StochasticIsoMP(), w0, **kw)
    if "threaded sweeps" not in threaded.stats.runner:
        pytest.skip("numba has one thread here: the sweeps are not threaded")
    serial = iso.solve(noisy, iso.StochasticIsoMP(), w0, threads=1, **kw)
    assert "threaded" not in serial.stats.runner
    assert float(np.abs(threaded.ys - serial.ys).max()) < 1e-13
    assert float(np.abs(threaded.ys[-1] - w0).max()) > 1e-3
