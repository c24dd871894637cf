r"""Isospectral and Lie–Poisson problems :math:`\dot W = [B(W), W]` on a space ``V``."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._errors import ArgumentTypeError, InvalidBError, ParameterError
from .algebras import Algebra
from .kernels import CompiledB, Kernel
from .noise import TransportNoise
from .splitting import Forcing, LinearPart, StochasticForcing

__all__ = ["IsospectralProblem"]

Array = NDArray[Any]


def _first_line(exc: Exception) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


@dataclass(frozen=True)
class IsospectralProblem:
    r"""The isospectral flow :math:`\dot W = [B(W), W]`, ``W`` in ``V``, ``B(W)`` in ``N(V)``.

    Parameters
    ----------
    B : callable, optional
        ``B(W)`` for ``W`` of shape ``(*batch, *algebra.shape)``, returning an array of shape
        ``(*batch, *algebra.normalizer.shape)`` with values in ``algebra.normalizer``. It must
        broadcast over leading axes (write ``np.swapaxes(W, -1, -2)``, not ``W.T``) unless
        ``vectorized=False``. May be omitted when ``kernel`` is given: ``B`` then evaluates
        the kernel's compiled function member by member (write ``B`` once).
    algebra : Algebra
        The space ``V`` (``iso.algebras.so(n)``, ...).
    hamiltonian : callable, optional
        ``H(W) -> (*batch,)`` real; only used for diagnostics. For a Lie–Poisson system
        :math:`B = (\nabla H)^\dagger` (see :meth:`from_hamiltonian`).
    B_jvp : callable, optional
        Directional derivative ``B_jvp(W, dW) = DB(W)[dW]``; makes Newton's Jacobian exact.
    lyapunov : callable, optional
        ``L(W) -> (*batch,)``, a function that is non-decreasing along the exact flow (e.g.
        ``Tr(WN)`` for the Brockett flow); the diagnostics report its largest decrease.
    invariants : mapping of str to callable, optional
        Further first integrals ``I(W) -> (*batch,)`` or ``(*batch, m)`` tracked by the
        diagnostics (e.g. a momentum map).
    vectorized : bool
        Whether ``B`` handles leading batch axes; if ``False`` it is applied member by member.
    name : str
        Name used in messages and output files.
    parameters : mapping
        The model parameters, recorded with results.
    kernel : Kernel or None
        Compiled description of the *same* ``B`` (:mod:`isoflow.kernels`): your own
        ``CompiledB(f, args)``, or a built-in ``ElementwiseLinear``, ``SpinNeighbourSum``,
        ``PairwiseVortex``. With a kernel, :func:`~isoflow.solve` runs the time loop in
        compiled code wherever the method and solver have a compiled path (same answer and
        iteration counts as the NumPy path to rounding). When both ``B`` and ``kernel`` are
        given they must agree (checked at the initial state when a run starts).
    linear_part : LinearPart or None
        A linear part ``L`` of the flow, :math:`\dot W = [B(W), W] + L W + F`, diagonal in an
        orthonormal basis (dissipation: viscosity, drag; :mod:`isoflow.splitting`). A problem
        with a linear part or a forcing is integrated by a split method,
        :class:`~isoflow.Strang`.
    forcing : Forcing, StochasticForcing or a sequence of them
        Forcings added to the flow (:class:`~isoflow.Forcing`: deterministic, steady or with
        time-dependent amplitudes; :class:`~isoflow.StochasticForcing`: white noise on modes
        of ``linear_part``). Stored as a tuple.
    noise : TransportNoise or None
        Stratonovich transport noise :math:`\sum_i [B_i(W), W] \circ d\beta_i`
        (:class:`isoflow.noise.TransportNoise`): the problem is then the stochastic
        Lie–Poisson system :math:`dW = [B(W), W]\,dt + \sum_i [B_i(W), W] \circ d\beta_i`,
        integrated by :class:`~isoflow.StochasticIsoMP` (the deterministic methods refuse it).
    observables : mapping of str to callable, optional
        Further quantities ``O(W) -> (*batch,)`` or ``(*batch, ...)`` saved with every state
        and drawn by ``isoflow plot``, for which no drift is reported: spectra, budget rates,
        or quantities that a forcing or a dissipation changes by design. The names must
        differ from those of ``invariants``.
    """

    B: Callable[[Array], Array] = None  # type: ignore[assignment]
    algebra: Algebra = None  # type: ignore[assignment]
    hamiltonian: Callable[[Array], Array] | None = None
    B_jvp: Callable[[Array, Array], Array] | None = None
    lyapunov: Callable[[Array], Array] | None = None
    invariants: Mapping[str, Callable[[Array], Array]] = field(default_factory=dict)
    vectorized: bool = True
    name: str = "isospectral problem"
    parameters: Mapping[str, Any] = field(default_factory=dict)
    kernel: Kernel | None = None
    linear_part: LinearPart | None = None
    forcing: Forcing | StochasticForcing | Sequence[Forcing | StochasticForcing] = ()
    noise: TransportNoise | None = None
    observables: Mapping[str, Callable[[Array], Array]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.algebra, Algebra):
            raise ArgumentTypeError(
                "algebra must be an isoflow Algebra (e.g. iso.algebras.so(3)), "
                f"got {self.algebra!r}"
            )
        if self.kernel is not None:
            if not isinstance(self.kernel, Kernel):
                raise ArgumentTypeError(
                    "kernel must be an isoflow kernel (iso.CompiledB(f), ElementwiseLinear, "
                    f"SpinNeighbourSum, PairwiseVortex) or None, got {self.kernel!r}"
                )
            self.kernel.check(self.algebra)
        if self.noise is not None:
            if not isinstance(self.noise, TransportNoise):
                raise ArgumentTypeError(
                    f"noise must be an iso.noise.TransportNoise or None, got {self.noise!r}"
                )
            self.noise.check(self.algebra)
        if self.B is None:
            if self.kernel is None:
                raise ArgumentTypeError(
                    "give B, or a kernel (e.g. iso.CompiledB(f)) to derive it from"
                )
            object.__setattr__(self, "B", self.kernel.python_B(self.algebra))
        if not callable(self.B):
            raise ArgumentTypeError(f"B must be callable, got {type(self.B).__name__}")
        self._check_split_parts()
        self._check_diagnostic_functions()

    def _check_diagnostic_functions(self) -> None:
        """Invariants and observables: callables under distinct string names."""
        for what, functions in (("invariants", self.invariants), ("observables", self.observables)):
            if not isinstance(functions, Mapping):
                raise ParameterError(
                    f"{what} must be a mapping of names to functions, got "
                    f"{type(functions).__name__}"
                )
            for name, fn in functions.items():
                if not isinstance(name, str) or not callable(fn):
                    raise ParameterError(
                        f"{what} must map names (str) to functions, got {name!r}: {fn!r}"
                    )
        both = sorted(set(self.invariants) & set(self.observables))
        if both:
            raise ParameterError(
                f"{', '.join(map(repr, both))} named both an invariant and an observable"
            )

    def _check_split_parts(self) -> None:
        """Check the linear part and the forcings against the space (typed one-line errors)."""
        if self.linear_part is not None:
            if not isinstance(self.linear_part, LinearPart):
                raise ParameterError(
                    "linear_part must be an isoflow LinearPart (iso.ModalLinearPart, "
                    f"iso.sphere.SphereDissipation) or None, got {self.linear_part!r}"
                )
            self.linear_part.check(self.algebra)
        terms: Any = self.forcing
        if isinstance(terms, (Forcing, StochasticForcing)):
            terms = (terms,)
        elif terms is None:
            terms = ()
        elif not isinstance(terms, (tuple, list)):
            raise ParameterError(
                "forcing must be an iso.Forcing, an iso.StochasticForcing or a sequence of "
                f"them, got {type(terms).__name__}"
            )
        terms = tuple(terms)
        for f in terms:
            if isinstance(f, Forcing):
                f.patterns(self.algebra)
            elif isinstance(f, StochasticForcing):
                f.checked(self.linear_part)
            else:
                raise ParameterError(
                    f"forcing terms must be iso.Forcing or iso.StochasticForcing, got {f!r}"
                )
        object.__setattr__(self, "forcing", terms)

    @property
    def forced_or_dissipative(self) -> bool:
        """Whether a linear part or a forcing changes the Casimirs and the energy by design."""
        return self.linear_part is not None or bool(self.forcing)

    @property
    def energy_changes(self) -> bool:
        """Whether the flow may change the energy (and the invariants other than the Casimirs)
        by design: a linear part or a forcing, transport noise, or a dissipation in ``B``,
        which a problem declares by its ``lyapunov`` function (a double bracket, Gilbert
        damping). The drifts of such quantities are then changes, not errors."""
        return self.forced_or_dissipative or self.noise is not None or self.lyapunov is not None

    # ---- evaluation ---------------------------------------------------------------------
    def evaluate_B(self, W: Array) -> Array:
        """``B(W)`` honouring :attr:`vectorized`, checked on every call.

        Raises
        ------
        InvalidBError
            ``B`` returned the wrong shape, a non-numeric array, or complex values for a real
            normalizer (cheap checks, so that a ``B`` that changes its output in the middle of
            a run stops it with a clear message instead of a wrong answer).
        """
        alg = self.algebra
        if self.vectorized:
            out = np.asarray(self.B(W))
        else:
            batch = alg.batch_shape(W)
            flat = W.reshape(-1, *alg.shape)
            out = np.stack([np.asarray(self.B(w)) for w in flat])
            out = out.reshape(*batch, *out.shape[1:])
        norm_alg = alg.normalizer
        expected = (*alg.batch_shape(W), *norm_alg.shape)
        if out.shape != expected:
            raise InvalidBError(
                f"B returned shape {out.shape}, expected {expected} (values in "
                f"{norm_alg.name}; B must broadcast over leading batch axes)"
            )
        if out.dtype.kind not in "iufc":
            raise InvalidBError(f"B returned non-numeric dtype {out.dtype}")
        if out.dtype.kind == "c" and not norm_alg.is_complex:
            raise InvalidBError(
                f"B returned complex values but its values must lie in the real algebra "
                f"{norm_alg.name}"
            )
        return out

    def evaluate_B_jvp(self, W: Array, dW: Array) -> Array:
        """``DB(W)[dW]`` honouring :attr:`vectorized` (requires :attr:`B_jvp`)."""
        assert self.B_jvp is not None
        if self.vectorized:
            return np.asarray(self.B_jvp(W, dW))
        batch = self.algebra.batch_shape(W)
        core = self.algebra.shape
        Wf = np.broadcast_to(W, dW.shape).reshape(-1, *core)
        dWf = dW.reshape(-1, *core)
        out = np.stack([np.asarray(self.B_jvp(w, d)) for w, d in zip(Wf, dWf, strict=True)])
        return out.reshape(*batch, *out.shape[1:])

    def vector_field(self, W: Array) -> Array:
        r"""The right-hand side :math:`[B(W), W]`."""
        return self.algebra.project(self.algebra.bracket(self.evaluate_B(W), W))

    def check_B(self, W: Array, rtol: float = 1e-8) -> Array:
        """Evaluate ``B(W)`` once and check shape, dtype, finiteness and normalizer membership.

        Parameters
        ----------
        W : ndarray, shape (*batch, *shape)
            States where ``B`` is evaluated (e.g. the initial state).
        rtol : float
            Relative tolerance of the membership test: ``B(W)`` may be at most
            ``1e-12 + rtol * norm(B(W))`` away from the normalizer (default ``1e-8``).

        Returns
        -------
        ndarray
            ``B(W)`` in the normalizer's dtype.

        Raises
        ------
        InvalidBError
            Naming what is wrong with ``B``'s output.
        """
        alg = self.algebra
        norm_alg = alg.normalizer
        try:
            out = self.evaluate_B(W)
        except InvalidBError as exc:
            self._check_broadcasting(W, exc)
            raise
        except Exception as exc:  # re-raise user errors with context, keep the cause
            self._check_broadcasting(W, exc)
            raise InvalidBError(f"B raised {type(exc).__name__}: {exc}") from exc
        self._check_broadcasting(W, None, out)
        if not np.all(np.isfinite(out)):
            raise InvalidBError("B returned non-finite values (NaN or Inf)")
        outc = out.astype(norm_alg.dtype, copy=False)
        if isinstance(self.kernel, CompiledB):
            unwritten = self.kernel.unwritten_entry(W, alg)
            if unwritten is not None:
                raise InvalidBError(
                    f"the kernel {self.kernel.name} leaves out{list(unwritten)} unwritten or "
                    "adds to it: the compiled loops do not zero out before a call, so write "
                    "every entry of out, zeros included"
                )
        if self.kernel is not None:
            fast = np.asarray(self.kernel.evaluate(W, alg))
            gap = float(np.max(np.abs(fast - outc))) if fast.shape == outc.shape else np.inf
            if not gap <= 1e-12 * max(1.0, float(np.max(np.abs(outc)))):
                if getattr(self.B, "isoflow_kernel", None) is self.kernel:  # B is the kernel's
                    raise InvalidBError(
                        f"the kernel {getattr(self.kernel, 'name', '')} gives other values for "
                        f"the same state (by {gap:.3e}): its function must depend on W and its "
                        "arguments only, and must not modify them"
                    )
                raise InvalidBError(
                    f"the problem's kernel {type(self.kernel).__name__} does not describe its B: "
                    f"they differ by {gap:.3e} at the initial state (the compiled fast path would "
                    "integrate a different flow)"
                )
        dist = norm_alg.distance(outc)
        tol = 1e-12 + rtol * norm_alg.norm(outc)
        if np.any(dist > tol):
            raise InvalidBError(
                f"B(W) is not in the normalizer {norm_alg.name} of {alg.name}: distance "
                f"{float(np.max(dist)):.3e} (tolerance {float(np.max(tol)):.3e}); the flow "
                f"W' = [B(W), W] would leave {alg.name}"
            )
        return outc

    def _check_broadcasting(
        self, W: Array, failure: Exception | None, out: Array | None = None
    ) -> None:
        """On an ensemble, compare ``B`` of the first member alone with what ``B`` of the
        ensemble did (``failure``: it raised, or ``out``: its values for that member).

        Raises
        ------
        InvalidBError
            ``B`` works on one state but fails or gives other values on the ensemble: it
            does not broadcast over leading axes (``W.T`` reverses *all* axes of a stack);
            or it raises for one member's state alone (that member named).
        """
        alg = self.algebra
        if not self.vectorized or not alg.batch_shape(W):
            return
        first = W.reshape(-1, *alg.shape)[0]
        try:
            alone = np.asarray(self.evaluate_B(first))
        except Exception:
            return  # B fails on one state too: its own error says why
        if failure is None:
            assert out is not None
            got = out.reshape(-1, *alone.shape)[0]
            scale = max(1.0, float(np.max(np.abs(alone))))
            if float(np.max(np.abs(got - alone))) <= 1e-10 * scale:
                return
            if self.kernel is not None and getattr(self.B, "isoflow_kernel", None) is self.kernel:
                raise InvalidBError(
                    f"the kernel {getattr(self.kernel, 'name', '')} gives other values for the "
                    "same state: its function must depend on W and its arguments only, and must "
                    "not modify them"
                )
            what = "gives other values for its first member than for that state alone"
        else:
            for j, member in enumerate(W.reshape(-1, *alg.shape)):
                try:
                    self.evaluate_B(member)
                except Exception as exc:  # that member's own state: bad input, named
                    raise InvalidBError(
                        f"B raised {type(exc).__name__} at the initial state of member {j}: "
                        f"{_first_line(exc)} (later in a run such a member fails alone)"
                    ) from exc
            what = f"fails on the ensemble ({type(failure).__name__}: {_first_line(failure)})"
        raise InvalidBError(
            f"B works on one state but {what}: on an ensemble of shape {W.shape} it must act "
            "on the last two axes (write np.swapaxes(W, -1, -2) or W.mT, not W.T, and @ or "
            "np.einsum with '...'), or give vectorized=False to call it member by member"
        ) from failure

    # ---- constructors -------------------------------------------------------------------
    @classmethod
    def from_hamiltonian(
        cls,
        algebra: Algebra,
        hamiltonian: Callable[[Array], Array],
        gradient: Callable[[Array], Array],
        **kwargs: Any,
    ) -> IsospectralProblem:
        r"""The Lie–Poisson system of ``H`` on ``V = g``, identified with ``g*`` by the pairing.

        With the real Frobenius pairing :math:`\langle A, X\rangle = \operatorname{Re}
        \operatorname{Tr}(A^\dagger X)` (:meth:`Algebra.inner`), ``gradient(W)`` must return
        :math:`\nabla H(W) \in V` and the flow is :math:`\dot W = [\nabla H(W)^\dagger, W]`
        (paper, eq. (2)), i.e. ``B = gradient^dagger``. ``algebra`` must provide ``dagger``.

        The gradient is always taken in ``algebra.inner``. For the vector forms
        (``so3_vectors``, ``sl2_vectors``) that is the Euclidean dot product, *half* the
        Frobenius pairing of the matrices: there ``gradient`` is the ordinary gradient and the
        flow is :math:`\dot w_i = w_i \times \nabla_i H` on :math:`(\mathbb{R}^3,\times)^N`
        (:math:`\dot w_i = w_i \times_L L \nabla_i H` on :math:`\mathfrak{sl}(2)^N`), twice as
        fast as the matrix Lie–Poisson flow of the same ``H``.

        Parameters
        ----------
        algebra : Algebra
            The space ``V``; it must have a ``dagger`` method.
        hamiltonian : callable
            ``H(W) -> (*batch,)``: the energy, recorded with the problem (the energy
            diagnostic); the flow uses ``gradient`` only.
        gradient : callable
            ``gradient(W) -> (*batch, *shape)``: :math:`\nabla H(W)` in ``algebra.inner``.
        **kwargs
            Further arguments of :class:`IsospectralProblem` (e.g. ``vectorized``,
            ``B_jvp``, ``parameters``).

        Returns
        -------
        IsospectralProblem

        Raises
        ------
        ArgumentTypeError
            ``algebra`` has no ``dagger``.
        """
        dagger = getattr(algebra, "dagger", None)
        if dagger is None:
            raise ArgumentTypeError(f"{algebra.name} does not define the dagger map needed for B")

        def B(W: Array) -> Array:
            return dagger(gradient(W))

        return cls(B=B, algebra=algebra, hamiltonian=hamiltonian, **kwargs)
