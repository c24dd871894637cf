r"""Compiled descriptions of ``B``: the protocol the compiled time loops run on.

A problem :math:`\dot W = [B(W), W]` may carry a *kernel* besides (or instead of) its Python
``B``: a numba-compiled function that evaluates ``B`` for **one** system,

.. code-block:: python

    @numba.njit(cache=True)
    def f(W, out, *args):      # W: one state, out: B(W) is written here
        ...

``W`` is one element of the space (an ``(n, n)`` real or complex matrix, or the ``(N, 3)``
array of a particle space), ``out`` an array of the same shape and of the normalizer's dtype,
and ``args`` the kernel's parameters (arrays and numbers, passed through unchanged). With a
kernel, the compiled time loops (:mod:`isoflow._compiled`) call ``f`` directly, on every state
layout; the NumPy path and the diagnostics use the Python ``B`` (which a problem derives from
the kernel when it is given no ``B``).

Kernels
-------
:class:`CompiledB`
    Your own ``f``: ``iso.IsospectralProblem(algebra=alg, kernel=iso.CompiledB(f, args))``.
:class:`ElementwiseLinear`
    :math:`B(W) = C \circ W`, optionally in a fixed unitary frame (rigid body, Toda, Brockett).
:class:`SpinNeighbourSum`
    :math:`B_i = c\,(w_{i-1} + w_{i+1})` on :math:`(\mathbb{R}^3,\times)^N` (Heisenberg chain).
:class:`PairwiseVortex`
    The point-vortex fields on the sphere and on the hyperbolic plane.

The built-in kernels are instances of the same protocol (their ``field`` is such an ``f``);
the compiled layer may use a specialized fused evaluation for some of them where a benchmark
shows that it pays (ensembles of elementwise kernels, long spin chains).

Compile time and caching
------------------------
The compiled loops are specialized on ``f``: the first run with a new ``f`` compiles them
(a few seconds, once per function and argument types; isoflow says so when it happens), and
with ``cache=True`` on ``f`` the result is stored in numba's cache (``NUMBA_CACHE_DIR``, by
default ``__pycache__`` beside the source) and loaded in later processes. Changing ``f``'s
source invalidates its entries. A function that cannot be cached (a closure over arrays, a
lambda in a notebook) still works; it is compiled again in every new process.

This module does not import numba; the built-in field functions live in
:mod:`isoflow._kernel_fields` and are compiled (or loaded from the cache) on first use.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._errors import ArgumentTypeError, InvalidBError, ParameterError, ShapeError

if TYPE_CHECKING:
    from .algebras import Algebra

__all__ = [
    "CompiledB",
    "ElementwiseLinear",
    "Kernel",
    "PairwiseVortex",
    "SpinNeighbourSum",
]

Array = NDArray[Any]


class Kernel:
    """Base of the compiled descriptions of ``B`` (see the module docstring).

    Subclasses provide :meth:`field` (the compiled ``f`` and its arguments) and may override
    :meth:`evaluate` with a NumPy formula and :meth:`check` with their own requirements on the
    space.
    """

    #: Name used in messages (compile notices, errors).
    name: str = "kernel"

    def field(self) -> tuple[Callable[..., None], tuple[Any, ...]]:  # pragma: no cover
        """``(f, args)``: the compiled ``f(W, out, *args)`` for one system."""
        raise NotImplementedError

    def check(self, algebra: Algebra) -> None:
        """Raise if the kernel cannot describe a ``B`` on ``algebra`` (wrong shape, space)."""

    def evaluate(self, W: ArrayLike, algebra: Algebra) -> Array:
        """``B(W)`` for ``W`` of shape ``(*batch, *algebra.shape)`` through the compiled ``f``.

        Members are evaluated one by one by a compiled loop into a new array of the
        normalizer's dtype.

        Parameters
        ----------
        W : array_like, shape (*batch, *algebra.shape)
            The states.
        algebra : Algebra
            The problem's space (its shape and dtype, and its normalizer's dtype).

        Returns
        -------
        ndarray, shape (*batch, *algebra.shape)

        Raises
        ------
        ShapeError
            ``W`` does not end in ``algebra.shape``.
        """
        return self._apply(W, algebra, 0.0)

    def _apply(self, W: ArrayLike, algebra: Algebra, fill: float) -> Array:
        """The compiled ``f`` on every member of ``W``, into an ``out`` filled with ``fill``."""
        from ._kernel_fields import apply_field

        f, args = self.field()
        Wa = np.ascontiguousarray(W, dtype=algebra.dtype)
        core = algebra.shape
        if Wa.shape[Wa.ndim - len(core) :] != core:
            raise ShapeError(
                f"{self.name}: W must have shape (*batch, {', '.join(map(str, core))}), "
                f"got {Wa.shape}"
            )
        batch = Wa.shape[: Wa.ndim - len(core)]
        flat = Wa.reshape(-1, *core)
        out = np.full(flat.shape, fill, dtype=algebra.normalizer.dtype)
        apply_field(f, args, flat, out)
        return out.reshape(*batch, *core)

    def python_B(self, algebra: Algebra) -> Callable[[Array], Array]:
        """A Python ``B`` (broadcasting over leading axes) that calls this kernel.

        Parameters
        ----------
        algebra : Algebra
            The space ``B`` acts on, handed to :meth:`evaluate`.

        Returns
        -------
        callable
            ``B(W) -> array``, tagged with this kernel (``B.isoflow_kernel``).
        """

        def B(W: Array) -> Array:
            return self.evaluate(W, algebra)

        B.__qualname__ = B.__name__ = f"B from {self.name}"
        B.isoflow_kernel = self  # type: ignore[attr-defined]  # B is this kernel's own
        return B


def _is_numba_dispatcher(f: Any) -> bool:
    return callable(f) and hasattr(f, "py_func") and hasattr(f, "signatures")


class CompiledB(Kernel):
    r"""``B`` given by your own numba-compiled function ``f(W, out, *args)`` for one system.

    Parameters
    ----------
    f : numba dispatcher
        ``@numba.njit(cache=True)`` function that writes ``B(W)`` into ``out``. ``W`` is one
        state, C-contiguous: an ``(n, n)`` matrix (``float64`` or ``complex128``, the space's
        dtype) or the ``(N, 3)`` ``float64`` array of a particle space; ``out`` has ``W``'s
        shape and the normalizer's dtype and holds garbage on entry (write every entry: a run
        checks it first, with ``out`` filled with NaN).
        ``f`` must not keep references to ``W`` or ``out`` and must not modify ``W``.
    args : tuple
        Extra arguments passed to ``f`` after ``out``: arrays and numbers, not nested tuples,
        lists or dicts (an ensemble's members run on numba threads, which cannot be handed
        a tuple nested in the arguments). They are
        passed unchanged on every call; arrays are not copied, so do not modify them during a
        run.
    name : str, optional
        Name for messages (default: the function's name).
    raises : bool, default True
        Whether ``f`` may raise (an explicit ``raise``, or a float division by zero under
        numba's default error model). A compiled run then keeps a copy of the arrays each call
        of its loop changes, so that the members whose ``f`` raised are redone alone and frozen
        at their last good state while the others go on. ``raises=False`` skips that copy (for
        Euler on the sphere at ``N = 1024``, about 100 MB a call: the state, its ring of stage
        offsets and its compensation); an ``f`` that raises anyway then ends the run with its
        exception. The built-in sphere models' fields (Euler, the quasi-geostrophic model,
        MHD), which contain no raise and divide by no variable, pass ``False``.

    Examples
    --------
    The so(n) rigid body :math:`B(W) = -C \circ W`, written once (in a module file, write
    ``@numba.njit(cache=True)``; numba can only cache functions that live in a file):

    >>> import numba, numpy as np, isoflow as iso
    >>> @numba.njit
    ... def rigid_body_B(W, out, C):
    ...     n = W.shape[0]
    ...     for i in range(n):
    ...         for j in range(n):
    ...             out[i, j] = -C[i, j] * W[i, j]
    >>> n = 6
    >>> d = 1.0 / np.arange(1, n + 1)
    >>> C = 0.5 * (d[:, None] + d[None, :])
    >>> prob = iso.IsospectralProblem(
    ...     algebra=iso.algebras.so(n), kernel=iso.CompiledB(rigid_body_B, (C,)))
    >>> sol = iso.solve(prob, iso.IsoMP(), iso.algebras.so(n).random(0), dt=0.1, n_steps=10)
    """

    def __init__(self, f: Callable[..., None], args: tuple[Any, ...] = (), *,
                 name: str | None = None, raises: bool = True) -> None:  # fmt: skip
        if not _is_numba_dispatcher(f):
            raise ArgumentTypeError(
                "CompiledB needs a numba-compiled function: decorate it with "
                f"@numba.njit(cache=True) (got {type(f).__name__})"
            )
        if not getattr(f, "targetoptions", {}).get("nopython", True):
            raise InvalidBError(
                f"CompiledB needs a nopython function, and {getattr(f, '__name__', 'f')} is "
                "compiled in object mode (forceobj=True or nopython=False): decorate it with "
                "@numba.njit(cache=True), or give the problem a Python B instead"
            )
        if not isinstance(args, tuple):
            raise ArgumentTypeError(f"CompiledB: args must be a tuple, got {type(args).__name__}")
        for k, a in enumerate(args):
            if isinstance(a, (tuple, list, dict)):
                raise ArgumentTypeError(
                    f"CompiledB: args[{k}] is a {type(a).__name__}; give arrays and numbers "
                    "only (numba's threads cannot be handed a tuple nested in the arguments: "
                    "flatten it, e.g. (C, (a, b)) -> (C, a, b))"
                )
        if not isinstance(raises, bool):
            raise ArgumentTypeError(f"CompiledB: raises must be True or False, got {raises!r}")
        self.f = f
        self.args = args
        self.name: str = name or str(getattr(f, "__name__", "CompiledB"))
        self.raises = raises

    def field(self) -> tuple[Callable[..., None], tuple[Any, ...]]:
        return self.f, self.args

    def unwritten_entry(self, W: ArrayLike, algebra: Algebra) -> tuple[int, ...] | None:
        """The index of the first entry of ``out`` that ``f`` leaves unwritten, or ``None``.

        ``f`` is called on ``W`` with ``out`` filled with NaN: an entry still NaN was either
        never written or added to (``out[i, j] += ...``), so ``f`` relied on ``out`` starting
        at zero. The compiled loops hand ``f`` the buffer of the previous call, so such an
        entry would keep a stale value there, while the NumPy path (``out`` zeroed) would not.

        Parameters
        ----------
        W : array_like, shape (*batch, *algebra.shape)
            States at which to call ``f``, one call a member; ``f`` must give finite values
            there (checked before by :meth:`~isoflow.IsospectralProblem.check_B`).
        algebra : Algebra
            The problem's space.

        Returns
        -------
        tuple of int or None
            The index into ``W``'s shape of the first NaN entry, or ``None`` when ``f``
            writes every entry.
        """
        probe = self._apply(W, algebra, np.nan)
        missing = np.argwhere(np.isnan(probe))
        return tuple(int(i) for i in missing[0]) if missing.size else None

    def __repr__(self) -> str:
        return f"CompiledB({self.name}, {len(self.args)} args)"


def _dense_sigma_space(algebra: Algebra) -> bool:
    from .algebras import Hermitian, SpecialOrthogonal, Symmetric, Unitary

    return isinstance(algebra, (SpecialOrthogonal, Unitary, Symmetric, Hermitian))


@dataclass(frozen=True, eq=False)
class ElementwiseLinear(Kernel):
    r"""``B(W) = C \circ W`` (entrywise product) with a fixed real ``n x n`` array ``C``, or
    :math:`B(W) = U\,\big(C \circ (U^\dagger W U)\big)\,U^\dagger` in a fixed unitary frame.

    Covers the generalized rigid body (:math:`C_{ij} = -(d_i + d_j)/2` on
    :math:`\mathfrak{so}(n)`), the Toda lattice and the Brockett flow :math:`B(W) = [N, W]`:
    with :math:`N = U \operatorname{diag}(\nu) U^\dagger` (``U = I`` when ``N`` is diagonal),
    :math:`[N, W] = U\,\big(C \circ (U^\dagger W U)\big)\,U^\dagger` with
    :math:`C_{ij} = \nu_i - \nu_j`. ``B`` lies in the normalizer when ``C`` is symmetric on the
    skew spaces :math:`\mathfrak{so}(n), \mathfrak{u}(n)` and antisymmetric on ``Sym(n)``,
    ``Herm(n)``.

    IsoMP commutes with the unitary change of frame :math:`W \mapsto U^\dagger W U` (it maps
    ``V``, the normalizer and every iterate of the step's fixed-point iteration to their
    counterparts), so the compiled loops run in the frame where ``B`` is entrywise and map
    the results back: the same steps and iterates up to rounding.

    Parameters
    ----------
    coeff : array_like, shape (n, n)
        The real coefficients ``C``.
    frame : array_like, shape (n, n), optional
        The unitary (orthogonal, for real spaces) ``U``; ``None`` means ``U = I``.
    """

    coeff: Array = field()
    frame: Array | None = None
    name = "ElementwiseLinear"

    def __post_init__(self) -> None:
        c = np.ascontiguousarray(np.asarray(self.coeff, dtype=np.float64))
        if c.ndim != 2 or c.shape[0] != c.shape[1]:
            raise ParameterError(f"ElementwiseLinear: coeff must be square, got shape {c.shape}")
        if not np.all(np.isfinite(c)):
            raise ParameterError("ElementwiseLinear: coeff has non-finite entries")
        c.setflags(write=False)
        object.__setattr__(self, "coeff", c)
        if self.frame is None:
            return
        U = np.asarray(self.frame)
        if U.dtype.kind not in "fc":
            U = U.astype(np.float64)
        U = np.ascontiguousarray(U)
        if U.shape != c.shape:
            raise ParameterError(
                f"ElementwiseLinear: frame must have the shape {c.shape} of coeff, got {U.shape}"
            )
        if not np.all(np.isfinite(U)):
            raise ParameterError("ElementwiseLinear: frame has non-finite entries")
        gap = float(np.max(np.abs(U.conj().T @ U - np.eye(U.shape[0]))))
        if not gap <= 1e-12 * U.shape[0]:
            raise ParameterError(
                f"ElementwiseLinear: frame is not unitary (|U^H U - I| = {gap:.2e})"
            )
        U.setflags(write=False)
        object.__setattr__(self, "frame", U)

    def field(self) -> tuple[Callable[..., None], tuple[Any, ...]]:
        from . import _kernel_fields as kf

        if self.frame is None:
            return kf.elementwise, (self.coeff,)
        U = self.frame
        return kf.elementwise_in_frame, (self.coeff, U, np.ascontiguousarray(U.conj().T))

    def check(self, algebra: Algebra) -> None:
        if not _dense_sigma_space(algebra):
            raise InvalidBError(
                f"ElementwiseLinear describes B on so(n), u(n), su(n), sym(n), herm(n), "
                f"not on {algebra.name}"
            )
        if self.coeff.shape != algebra.shape:
            raise InvalidBError(
                f"ElementwiseLinear: coeff has shape {self.coeff.shape}, but {algebra.name} "
                f"holds {algebra.shape} matrices"
            )
        if self.frame is not None and np.iscomplexobj(self.frame) and not algebra.is_complex:
            raise InvalidBError(
                f"ElementwiseLinear: a complex frame cannot act on the real space {algebra.name}"
            )

    def evaluate(self, W: ArrayLike, algebra: Algebra | None = None) -> Array:
        """``C * W``, or ``U (C * (U^H W U)) U^H`` with a frame (NumPy).

        Parameters
        ----------
        W : array_like, shape (*batch, *coeff.shape)
            The states.
        algebra : Algebra, optional
            Unused (the formula needs no space); accepted for the :class:`Kernel` interface.

        Returns
        -------
        ndarray, shape (*batch, *coeff.shape)
        """
        Wa = np.asarray(W)
        if self.frame is None:
            return self.coeff * Wa
        U = self.frame
        Uh = U.conj().T
        return U @ (self.coeff * (Uh @ Wa @ U)) @ Uh


def _finite_real(value: Any, what: str) -> float:
    """``value`` as a float, if it is a finite real number (not a bool); else a
    :class:`ParameterError` naming :class:`SpinNeighbourSum`'s parameter ``what``."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ParameterError(f"SpinNeighbourSum: {what} must be a real number, got {value!r}")
    if not np.isfinite(value):
        raise ParameterError(f"SpinNeighbourSum: {what} must be finite, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class SpinNeighbourSum(Kernel):
    r"""``B_i(w) = c\,(w_{i-1} + w_{i+1})`` on :math:`(\mathbb{R}^3,\times)^N`, periodic, with
    optional Gilbert damping.

    The Heisenberg chain is ``c = -1`` (:math:`B_i = -\nabla_i H`,
    :math:`H = \sum_i w_i\cdot w_{i+1}`). With damping :math:`\lambda > 0`,

    .. math:: B_i(w) = h_i + \lambda\, w_i \times h_i, \qquad h_i = c\,(w_{i-1} + w_{i+1}),

    the Landau–Lifshitz–Gilbert field in double-bracket form (``docs/theory/stochastic.rst``;
    :func:`isoflow.models.heisenberg_chain` with ``damping``). Chains of two spins or more run
    on the chain's fused compiled sweeps, with damping or without.

    Parameters
    ----------
    coupling : float
        The factor ``c``.
    damping : float
        The Gilbert damping :math:`\lambda \ge 0` (default 0).
    """

    coupling: float = -1.0
    damping: float = 0.0
    name = "SpinNeighbourSum"

    def __post_init__(self) -> None:
        object.__setattr__(self, "coupling", _finite_real(self.coupling, "coupling"))
        lam = _finite_real(self.damping, "damping")
        if lam < 0:
            raise ParameterError(f"SpinNeighbourSum: damping must be >= 0, got {lam!r}")
        object.__setattr__(self, "damping", lam + 0.0)  # -0.0 becomes 0.0

    def field(self) -> tuple[Callable[..., None], tuple[Any, ...]]:
        from . import _kernel_fields as kf

        if self.damping == 0.0:
            return kf.neighbour_sum, (self.coupling,)
        return kf.neighbour_sum_gilbert, (self.coupling, self.damping)

    def check(self, algebra: Algebra) -> None:
        from .algebras import SpinVectors

        if not isinstance(algebra, SpinVectors):
            raise InvalidBError(
                f"SpinNeighbourSum describes B on (R^3, x)^N, not on {algebra.name}"
            )

    def evaluate(self, W: ArrayLike, algebra: Algebra | None = None) -> Array:
        """``h_i + damping w_i x h_i``, ``h_i = c (w_{i-1} + w_{i+1})`` over the particle axis
        (NumPy), periodic.

        Parameters
        ----------
        W : array_like, shape (*batch, N, 3)
            Spins.
        algebra : Algebra, optional
            Unused; accepted for the :class:`Kernel` interface.

        Returns
        -------
        ndarray, shape (*batch, N, 3)
        """
        Wa = np.asarray(W, dtype=np.float64)
        H = self.coupling * (np.roll(Wa, 1, axis=-2) + np.roll(Wa, -1, axis=-2))
        if self.damping == 0.0:
            return H
        return H + self.damping * np.cross(Wa, H)


#: The two geometries of :class:`PairwiseVortex`.
VortexGeometry = Literal["sphere", "hyperbolic"]
_VORTEX_COEFFICIENT = {"sphere": 1.0 / (4.0 * np.pi), "hyperbolic": -1.0 / np.pi}


@dataclass(frozen=True, eq=False)
class PairwiseVortex(Kernel):
    r"""The pairwise point-vortex field on :math:`(\mathbb{R}^3,\times)^N` or
    :math:`(\mathbb{R}^3,\times_L)^N`:

    .. math::

        B_i(w) = c \sum_{j \ne i} \Gamma_j\, f(w_i \cdot w_j)\, w_j ,
        \qquad i = 1, \dots, N,

    with, for ``geometry``

    * ``"sphere"`` (point vortices on the unit sphere,
      :func:`~isoflow.models.sphere_vortices`, on ``so3_vectors(N)``): the Euclidean dot
      :math:`a \cdot b`, :math:`f(D) = 1/(1 - D)` and :math:`c = 1/(4\pi)`;
    * ``"hyperbolic"`` (point vortices on the hyperboloid,
      :func:`~isoflow.models.hyperbolic_vortices`, on ``sl2_vectors(N)``): the Lorentzian dot
      :math:`a \cdot_L b = a_1 b_1 + a_2 b_2 - a_3 b_3`,
      :math:`f(D) = 1/(D^2 - 1)`, evaluated as :math:`1/((D - 1)(D + 1))`, and
      :math:`c = -1/\pi`.

    The pair factor :math:`f(w_i \cdot w_j)` is symmetric in ``i, j``; the compiled field
    computes it once per pair (:math:`N(N-1)/2` divisions per evaluation of ``B``).

    Parameters
    ----------
    circulations : array_like, shape (N,)
        The vortex strengths :math:`\Gamma_j`, real and finite (stored as a read-only
        ``float64`` copy).
    geometry : {"sphere", "hyperbolic"}
        Which dot product, pair function ``f`` and constant ``c``.

    Raises
    ------
    ParameterError
        ``circulations`` not a non-empty real finite vector, or an unknown ``geometry``.
    """

    circulations: Array = field()
    geometry: VortexGeometry = field()
    name = "PairwiseVortex"

    def __post_init__(self) -> None:
        if not isinstance(self.geometry, str) or self.geometry not in _VORTEX_COEFFICIENT:
            raise ParameterError(
                f"PairwiseVortex: geometry must be 'sphere' or 'hyperbolic', got {self.geometry!r}"
            )
        raw = np.asarray(self.circulations)
        if raw.dtype.kind not in "iuf":
            raise ParameterError(
                f"PairwiseVortex: circulations must be real numbers, got dtype {raw.dtype}"
            )
        g = np.array(raw, dtype=np.float64, copy=True)
        if g.ndim != 1 or g.shape[0] < 1:
            raise ParameterError(
                f"PairwiseVortex: circulations must have shape (N,) with N >= 1, got {g.shape}"
            )
        if not np.all(np.isfinite(g)):
            raise ParameterError(f"PairwiseVortex: circulations must be finite, got {g}")
        g.setflags(write=False)
        object.__setattr__(self, "circulations", g)

    @property
    def N(self) -> int:
        """Number of vortices."""
        return int(self.circulations.shape[0])

    @property
    def coefficient(self) -> float:
        r"""The constant ``c``: :math:`1/(4\pi)` on the sphere, :math:`-1/\pi` hyperbolic."""
        return _VORTEX_COEFFICIENT[self.geometry]

    def field(self) -> tuple[Callable[..., None], tuple[Any, ...]]:
        from . import _kernel_fields as kf

        f = kf.vortex_sphere if self.geometry == "sphere" else kf.vortex_hyperbolic
        return f, (self.circulations, self.coefficient)

    def check(self, algebra: Algebra) -> None:
        from .algebras import SL2Vectors, SpinVectors

        space = SpinVectors if self.geometry == "sphere" else SL2Vectors
        if type(algebra) is not space:
            raise InvalidBError(
                f"PairwiseVortex(geometry={self.geometry!r}) describes B on "
                f"{'(R^3, x)^N' if space is SpinVectors else '(R^3, x_L)^N'}, "
                f"not on {algebra.name}"
            )
        if algebra.shape != (self.N, 3):
            raise InvalidBError(
                f"PairwiseVortex: {self.N} circulations for a space of {algebra.shape[0]} particles"
            )

    def evaluate(self, W: ArrayLike, algebra: Algebra | None = None) -> Array:
        """``B(W)`` for ``W`` of shape ``(*batch, N, 3)`` (NumPy).

        Parameters
        ----------
        W : array_like, shape (*batch, N, 3)
            Vortex positions, one row per vortex.
        algebra : Algebra, optional
            Unused (the geometry is the kernel's own); accepted for the :class:`Kernel`
            interface.

        Returns
        -------
        ndarray, shape (*batch, N, 3)

        Raises
        ------
        ShapeError
            ``W`` does not end in ``(N, 3)``.
        """
        Wa = np.asarray(W, dtype=np.float64)
        N = self.N
        if Wa.ndim < 2 or Wa.shape[-2:] != (N, 3):
            raise ShapeError(f"PairwiseVortex: W must have shape (*batch, {N}, 3), got {Wa.shape}")
        if self.geometry == "sphere":
            D = np.einsum("...ik,...jk->...ij", Wa, Wa)
            den = 1.0 - D
        else:
            D = np.einsum("...ik,...jk->...ij", Wa * np.array([1.0, 1.0, -1.0]), Wa)
            den = (D - 1.0) * (D + 1.0)
        off = ~np.eye(N, dtype=bool)
        with np.errstate(divide="ignore", invalid="ignore"):
            K = np.where(off, self.circulations / np.where(off, den, 1.0), 0.0)
        return self.coefficient * np.einsum("...ij,...jk->...ik", K, Wa)
