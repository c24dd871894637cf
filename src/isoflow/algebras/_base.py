r"""The interface every space ``V`` implements, and the shared machinery of matrix algebras.

A state of an isospectral flow :math:`\dot W = [B(W), W]` lives in a real vector space ``V``
(a matrix space such as :math:`\mathfrak{so}(n)` or a compact vector form such as
:math:`(\mathbb{R}^3, \times)^N`), and ``B`` takes values in the normalizer algebra
:math:`\mathfrak{n}(V)` of ``V``. Methods only talk to a space through :class:`Algebra`:

* ``bracket_and_triple(B, X)`` returns :math:`([B, X],\; B X B)`, the two products one
  iteration of the isospectral minimal midpoint needs;
* ``project`` maps onto ``V`` (used to keep iterates in ``V`` despite rounding);
* ``inner`` is the real pairing used for gradients, coordinates and norms.

Arrays carry leading batch axes: an array of shape ``(*batch, *algebra.shape)`` is an ensemble,
and every operation broadcasts over ``batch``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    import scipy.sparse as sp

from .._errors import (
    DtypeError,
    NonFiniteError,
    NotInSpaceError,
    ParameterError,
    ShapeError,
    UnsupportedAlgebraError,
)
from .._reductions import sum_of_squares, trace

__all__ = ["Algebra", "MatrixAlgebra"]

Array = NDArray[Any]


class Algebra(ABC):
    """A real vector space of states ``V`` together with the operations methods need.

    Subclasses define the element shape, the dtype, the normalizer, the projection and the
    products. Everything else (norms, distances, membership, coordinates) is derived here.

    Attributes
    ----------
    name : str
        Human-readable name, e.g. ``"so(10)"``.
    shape : tuple of int
        Shape of one element (``(n, n)`` for matrices, ``(N, 3)`` for vector forms).
    dtype : numpy.dtype
        ``float64`` for real spaces, ``complex128`` for complex ones.
    """

    name: str
    shape: tuple[int, ...]
    dtype: np.dtype[Any]

    # ---- what a space must provide -------------------------------------------------------
    @property
    @abstractmethod
    def normalizer(self) -> Algebra:
        """The space ``B`` must take values in, so that ``[B, X]`` stays in ``V``."""

    @property
    def stage_algebra(self) -> Algebra:
        r"""The space the midpoint stage ``X`` of IsoMP lives in.

        ``V`` itself for every space of the paper except :math:`\mathfrak{su}(n)`: there
        ``Tr(B X B)`` does not vanish, so ``X`` has a central part and lives in
        :math:`\mathfrak{u}(n)`, while ``W_{k+1} = W_k + h [B(X), X]`` is traceless again.
        """
        return self

    @abstractmethod
    def project(self, W: Array) -> Array:
        """Orthogonal projection onto ``V`` in the pairing :meth:`inner`.

        Parameters
        ----------
        W : ndarray, shape (*batch, *shape)
            Elements of the ambient space (for matrix spaces, any ``n x n`` matrices).

        Returns
        -------
        ndarray, shape (*batch, *shape)
        """

    @abstractmethod
    def bracket(self, A: Array, X: Array) -> Array:
        """The Lie bracket ``[A, X]`` of an element ``A`` of the normalizer with ``X``."""

    @abstractmethod
    def bracket_and_triple(self, B: Array, X: Array) -> tuple[Array, Array]:
        """Return ``([B, X], B X B)`` for ``B`` in the normalizer and ``X`` in ``V``.

        Both results lie in ``V`` (up to rounding for the triple product; callers project).
        """

    #: Whether :meth:`solve_stage` gives IsoMP's stage for a given field in closed form.
    closed_form_stage: bool = False

    def solve_stage(self, W: Array, B: Array, h: float) -> tuple[Array, Array]:
        r"""IsoMP's stage for a given field in closed form, on spaces with
        :attr:`closed_form_stage`.

        The ``X`` with :math:`W = (I - \tfrac h2 B)\, X\, (I + \tfrac h2 B)` for a fixed ``B``,
        and the bracket ``C`` the step's finish adds, :math:`W_{k+1} = W + h C`. IsoMP then
        iterates :math:`X \leftarrow X(B(X))` instead of the plain map: the same fixed point.

        Parameters
        ----------
        W : ndarray, shape (*batch, *shape)
            The step's state.
        B : ndarray, shape (*batch, *shape)
            The field.
        h : float
            The step size.

        Returns
        -------
        X, C : ndarray

        Raises
        ------
        NotImplementedError
            On spaces without a closed form.
        """
        raise NotImplementedError(f"{self.name} has no closed-form stage")

    def solve_stage_jvp(self, W: Array, B: Array, dB: Array, h: float) -> Array:
        """The derivative of :meth:`solve_stage`'s ``X`` along ``dB`` (for Newton's method).

        Raises
        ------
        NotImplementedError
            On spaces without :meth:`solve_stage`.
        """
        raise NotImplementedError(f"{self.name} has no closed-form stage")

    @abstractmethod
    def casimirs(self, W: Array) -> Array:
        """Invariants of every isospectral flow on ``V``, shape ``(*batch, m)``.

        Parameters
        ----------
        W : ndarray, shape (*batch, *shape)
            Elements of ``V``.

        Returns
        -------
        ndarray, shape (*batch, m)
        """

    def casimir_scale(self, W0: Array) -> Array:
        """Natural size of each Casimir component at ``W0``, to make drifts relative.

        Parameters
        ----------
        W0 : ndarray, shape (*batch, *shape)
            Elements of ``V`` (the initial states).

        Returns
        -------
        ndarray, shape (*batch, m)
            By default the :meth:`norm` of ``W0`` (at least the smallest positive float) for
            every component of :meth:`casimirs`.
        """
        C = self.casimirs(W0)
        norm = np.maximum(self.norm(W0), np.finfo(float).tiny)
        return np.broadcast_to(norm[..., None], C.shape)

    @abstractmethod
    def _basis_matrix(self) -> sp.csr_array:
        """Sparse ``(dim, m)`` matrix whose rows are an orthonormal basis of ``V``,
        written in the real flat representation of :meth:`_flatten`."""

    # ---- matrix representation -----------------------------------------------------------
    def to_matrix(self, W: Array) -> Array:
        """Matrices representing ``W`` (an element of ``V`` or of its normalizer).

        A Lie algebra homomorphism for :meth:`bracket`,
        ``to_matrix(bracket(A, X)) = [to_matrix(A), to_matrix(X)]``, used by methods that need
        general matrix products (e.g. :class:`~isoflow.IsoSyRK`). Matrix spaces return ``W``;
        the compact vector forms return one small matrix per particle,
        shape ``(*batch, N, k, k)``.

        Parameters
        ----------
        W : ndarray, shape (*batch, *shape)
            Elements of ``V`` or of its normalizer.

        Raises
        ------
        UnsupportedAlgebraError
            The space has no matrix representation.
        """
        raise UnsupportedAlgebraError(f"{self.name} has no matrix representation")

    def from_matrix(self, M: Array) -> Array:
        """Inverse of :meth:`to_matrix` on its image (not projected: callers project).

        Parameters
        ----------
        M : ndarray
            Matrices of the shape :meth:`to_matrix` returns.

        Raises
        ------
        UnsupportedAlgebraError
            The space has no matrix representation.
        """
        raise UnsupportedAlgebraError(f"{self.name} has no matrix representation")

    # ---- derived machinery ----------------------------------------------------------------
    @property
    def core_ndim(self) -> int:
        """Number of trailing axes that make up one element."""
        return len(self.shape)

    @property
    def is_complex(self) -> bool:
        """Whether elements are stored as complex numbers."""
        return bool(np.issubdtype(self.dtype, np.complexfloating))

    @cached_property
    def basis_matrix(self) -> sp.csr_array:
        """Orthonormal basis of ``V`` as a sparse ``(dim, m)`` matrix (cached)."""
        return self._basis_matrix()

    @property
    def dim(self) -> int:
        """Real dimension of ``V``."""
        return int(self.basis_matrix.shape[0])

    def batch_shape(self, W: Array) -> tuple[int, ...]:
        """Leading (ensemble) axes of an array of elements.

        Parameters
        ----------
        W : ndarray, shape (*batch, *shape)
            Elements (only the shape is read; the trailing :attr:`core_ndim` axes are
            dropped, whatever their lengths).

        Returns
        -------
        tuple of int
            ``batch``.
        """
        return tuple(W.shape[: W.ndim - self.core_ndim])

    def inner(self, A: Array, X: Array) -> Array:
        r"""Real pairing :math:`\langle A, X\rangle = \operatorname{Re}\sum \bar A_{ij} X_{ij}`.

        For matrices this is the Frobenius pairing
        :math:`\operatorname{Re}\operatorname{Tr}(A^\dagger X)` of the paper; gradients,
        coordinates and the norm :meth:`norm` all refer to it.
        """
        axes = tuple(range(-self.core_ndim, 0))
        return np.real(np.sum(np.conj(A) * X, axis=axes))

    def norm(self, W: Array) -> Array:
        """Norm induced by :meth:`inner` (the Frobenius norm for matrices), per member.

        Parameters
        ----------
        W : ndarray, shape (*batch, *shape)
            Elements (of ``V`` or of the ambient space).

        Returns
        -------
        ndarray, shape (*batch,)
        """
        axes = tuple(range(-self.core_ndim, 0))
        return np.sqrt(np.sum(np.abs(W) ** 2, axis=axes))

    def distance(self, W: Array) -> Array:
        """Distance from ``W`` to ``V`` in :meth:`norm`, per ensemble member."""
        return self.norm(W - self.project(W))

    def contains(self, W: ArrayLike, rtol: float = 1e-10, atol: float = 1e-12) -> Array:
        """Membership test ``distance(W) <= atol + rtol * norm(W)``, per member."""
        Wa = np.asarray(W)
        if Wa.shape[Wa.ndim - self.core_ndim :] != self.shape:
            return np.zeros(Wa.shape[: max(Wa.ndim - self.core_ndim, 0)], dtype=bool)
        if self.is_complex is False and np.iscomplexobj(Wa) and np.any(np.imag(Wa) != 0):
            return np.zeros(self.batch_shape(Wa), dtype=bool)
        Wc = Wa.astype(self.dtype) if not np.iscomplexobj(Wa) or self.is_complex else Wa.real
        return self.distance(Wc) <= atol + rtol * self.norm(Wc)

    def zeros(self, batch: tuple[int, ...] = ()) -> Array:
        """The zero element (an ensemble of them for a non-empty ``batch``)."""
        return np.zeros((*batch, *self.shape), dtype=self.dtype)

    def random(
        self,
        seed: int | np.random.Generator | None = None,
        batch: tuple[int, ...] = (),
        scale: float = 1.0,
    ) -> Array:
        """A random element: Gaussian coordinates in the orthonormal basis, times ``scale``.

        Parameters
        ----------
        seed : int, numpy.random.Generator or None
            Seed or generator (``numpy.random.default_rng`` semantics).
        batch : tuple of int
            Ensemble shape.
        scale : float
            Standard deviation of each coordinate.
        """
        from .._seeds import generator

        rng = generator(seed, f"{self.name}.random: seed")
        _require_memory(
            float(np.prod(batch, dtype=np.float64)) * self.dim * 8.0, 4.0,
            f"{self.name}.random: batch {tuple(batch)}",
        )  # fmt: skip
        coords = rng.standard_normal((*batch, self.dim)) * scale
        return self.from_coords(coords)

    # ---- coordinates ---------------------------------------------------------------------
    def _flatten(self, W: Array) -> Array:
        """Real flat representation: ``(*batch, m)`` with ``m = size`` (real) or ``2 size``."""
        batch = self.batch_shape(W)
        flat = W.reshape(*batch, -1)
        if self.is_complex:
            return np.concatenate([flat.real, flat.imag], axis=-1)
        return np.asarray(flat.real if np.iscomplexobj(flat) else flat, dtype=np.float64)

    def _unflatten(self, v: Array) -> Array:
        batch = v.shape[:-1]
        if self.is_complex:
            half = v.shape[-1] // 2
            v = v[..., :half] + 1j * v[..., half:]
        return np.asarray(v, dtype=self.dtype).reshape(*batch, *self.shape)

    @cached_property
    def _coordinate_maps(self) -> tuple[Any, Any]:
        """``(basis, basis^T)``: dense for small spaces (fast), sparse otherwise (O(n^2) memory)."""
        basis = self.basis_matrix
        if basis.shape[0] * basis.shape[1] <= 2**20:
            dense = basis.toarray()
            return dense, np.ascontiguousarray(dense.T)
        return basis, basis.T.tocsr()

    def to_coords(self, W: Array) -> Array:
        """Coordinates of ``W`` in the orthonormal basis of ``V``, shape ``(*batch, dim)``.

        Components of ``W`` orthogonal to ``V`` are dropped (this is the adjoint of
        :meth:`from_coords`).
        """
        flat = self._flatten(np.asarray(W))
        basis, _ = self._coordinate_maps
        rows = flat.reshape(-1, flat.shape[-1])
        coords = rows @ basis.T if isinstance(basis, np.ndarray) else (basis @ rows.T).T
        return np.asarray(coords).reshape(*flat.shape[:-1], self.dim)

    def _coords_array(self, coords: ArrayLike) -> Array:
        """``coords`` as floats, checked to have a trailing axis of length :attr:`dim`."""
        c = np.asarray(coords, dtype=np.float64)
        if c.shape[-1:] != (self.dim,):
            raise ShapeError(
                f"coordinates for {self.name} must have trailing axis of length {self.dim}, "
                f"got shape {c.shape}"
            )
        return c

    def from_coords(self, coords: ArrayLike) -> Array:
        """The element of ``V`` with the given coordinates, shape ``(*batch, *shape)``.

        Parameters
        ----------
        coords : array_like, shape (*batch, dim)
            Coordinates in the orthonormal basis of ``V`` (:attr:`basis_matrix`), converted to
            float.

        Returns
        -------
        ndarray, shape (*batch, *shape)

        Raises
        ------
        ShapeError
            The last axis of ``coords`` is not of length :attr:`dim`.
        """
        c = self._coords_array(coords)
        basis, basis_t = self._coordinate_maps
        rows = c.reshape(-1, self.dim)
        flat = rows @ basis if isinstance(basis, np.ndarray) else (basis_t @ rows.T).T
        return self._unflatten(np.asarray(flat).reshape(*c.shape[:-1], -1))

    # ---- validation ----------------------------------------------------------------------
    def validate(
        self,
        W: ArrayLike,
        what: str = "state",
        rtol: float = 1e-10,
        atol: float = 1e-12,
        *,
        project: bool = True,
    ) -> Array:
        """Check that ``W`` is an (ensemble of) element(s) of ``V`` and return it projected.

        Integer and float32 input is converted to the algebra's dtype; complex input for a
        real space is rejected. With ``project=False`` the checked values are returned as
        they are (in the algebra's dtype): a restart continues from exactly the state a run
        held, and a projection is not idempotent in floating point for every space (the
        trace removal of ``su(n)`` is not).

        Parameters
        ----------
        W : array_like, shape (*batch, *shape)
            The element(s) to check.
        what : str
            Names ``W`` in the error messages (default ``"state"``).
        rtol, atol : float
            Relative and absolute tolerance of the distance to ``V`` (defaults ``1e-10`` and
            ``1e-12``).
        project : bool
            Whether to return the projection onto ``V`` (default) or the checked values.

        Returns
        -------
        ndarray, shape (*batch, *shape)
            ``W`` in the algebra's dtype, projected unless ``project=False``.

        Raises
        ------
        DtypeError
            Non-numeric data, or complex data for a real space.
        ShapeError
            Trailing axes differ from :attr:`shape`.
        NonFiniteError
            NaN or Inf entries.
        NotInSpaceError
            ``distance(W) > atol + rtol * norm(W)`` for some member (the message gives it).
        """
        Wa = np.asarray(W)
        if Wa.dtype.kind not in "biufc" or Wa.dtype.kind == "b":
            raise DtypeError(f"{what} must be a numeric array, got dtype {Wa.dtype}")
        if Wa.dtype.kind == "c" and not self.is_complex:
            raise DtypeError(
                f"{what} is complex ({Wa.dtype}) but {self.name} is a real space; "
                "pass real data (e.g. W.real) if the imaginary part is meant to be zero"
            )
        if Wa.shape[max(Wa.ndim - self.core_ndim, 0) :] != self.shape or Wa.ndim < self.core_ndim:
            raise ShapeError(
                f"{what} must have shape (*batch, {', '.join(map(str, self.shape))}) for "
                f"{self.name}, got {Wa.shape}"
            )
        _require_memory(
            float(Wa.size) * np.dtype(self.dtype).itemsize,
            4.0,
            f"the {what} (an ensemble of shape {Wa.shape})",
        )  # its copies and the checks' temporaries; a broadcast view costs no memory itself
        Wa = Wa.astype(self.dtype, copy=False)
        if not np.all(np.isfinite(Wa)):
            raise NonFiniteError(f"All entries of the {what} must be finite (found NaN or Inf).")
        dist = self.distance(Wa)
        tol = atol + rtol * self.norm(Wa)
        if np.any(dist > tol):
            worst = float(np.max(dist))
            raise NotInSpaceError(
                f"{what} is not in {self.name}: distance {worst:.3e} exceeds tolerance "
                f"{float(np.max(tol)):.3e}",
                distance=worst,
                tolerance=float(np.max(tol)),
            )
        return self.project(Wa) if project else Wa

    def __repr__(self) -> str:
        return f"<algebra {self.name}>"


class MatrixAlgebra(Algebra):
    r"""A space of ``n x n`` matrices cut out by an exact involution ``sigma``.

    ``V = {X : sigma(X) = X}`` (plus ``Tr X = 0`` where :attr:`traceless`), where ``sigma`` is a
    signed permutation of the real entries (transpose, conjugate transpose, negation, or
    conjugation by a symplectic ``J``). Hence

    * the projection :math:`(Y + \sigma(Y))/2` is exact and idempotent in floating point;
    * for ``B`` in the normalizer and ``X`` in ``V`` one has :math:`XB = -\sigma(BX)`, so the
      commutator costs one matrix product: :math:`[B, X] = P + \sigma(P)` with ``P = B X``,
      and it lies in ``V`` exactly. The triple product is ``P B``, a second product.

    Subclasses set ``sigma`` (or ``None`` for ``gl(n)``), the normalizer and the Casimirs.

    Parameters
    ----------
    n : int
        Matrix size (a positive integer).
    dtype : numpy dtype
        Dtype of the elements (``float64`` for real, ``complex128`` for complex spaces).
    name : str
        Name of the space in messages and records (e.g. ``"so(3)"``).

    Raises
    ------
    ParameterError
        ``n`` is not a positive integer.
    """

    #: Whether elements have zero trace on top of ``sigma(X) = X``.
    traceless: bool = False
    #: Whether ``XB = -sigma(BX)`` holds for the normalizer, enabling the one-product bracket.
    structured: bool = True
    #: ``s`` where ``sigma(Y) = s conj(Y)^T`` (``None``: another involution); such spaces get
    #: the compiled :meth:`distance` for large arrays.
    transpose_sign: int | None = None

    def __init__(self, n: int, dtype: Any, name: str) -> None:
        if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < 1:
            raise ParameterError(f"matrix size n must be a positive integer, got {n!r}")
        self.n = int(n)
        self.shape = (self.n, self.n)
        self.dtype = np.dtype(dtype)
        self.name = name

    @abstractmethod
    def sigma(self, Y: Array) -> Array:
        """The involution defining ``V`` (exact in floating point).

        Parameters
        ----------
        Y : ndarray, shape (*batch, n, n)
            Matrices.

        Returns
        -------
        ndarray, shape (*batch, n, n)
        """

    def project(self, W: Array) -> Array:
        r"""The exact projection :math:`(W + \sigma(W))/2` onto ``V`` (trace removed where
        :attr:`traceless`).

        Parameters
        ----------
        W : ndarray, shape (*batch, n, n)
            Matrices.

        Returns
        -------
        ndarray, shape (*batch, n, n)
        """
        P = 0.5 * (W + self.sigma(W))
        if self.traceless:
            tr = np.trace(P, axis1=-2, axis2=-1) / self.n
            P = P - tr[..., None, None] * np.eye(self.n, dtype=P.dtype)
        return P

    def norm(self, W: Array) -> Array:
        """Frobenius norm per member (:meth:`Algebra.norm`), summed without a temporary of
        ``W``'s size."""
        return np.sqrt(_sum_of_squares(np.asarray(W)))

    def distance(self, W: Array) -> Array:
        r"""Frobenius distance to ``V`` per member: the norm of ``W - P(W) = (W - sigma(W))/2``
        (plus the trace part :math:`\operatorname{Tr}(P(W))/n\,I` where :attr:`traceless`),
        with one temporary of ``W``'s size (this runs on every saved state of a run,
        :func:`isoflow._stepping.stop_members_leaving_the_space`)."""
        if type(self).project is not MatrixAlgebra.project:  # a space with its own projection
            return super().distance(W)
        Wa = np.asarray(W)
        if (
            self.transpose_sign is not None
            and self.n * self.n >= _COMPILED_DISTANCE_SIZE
            and Wa.dtype in (np.float64, np.complex128)
        ):
            from .._distance_compiled import distances

            flat = np.ascontiguousarray(Wa).reshape(-1, self.n, self.n)
            out = np.empty(flat.shape[0])
            distances(flat, float(self.transpose_sign), self.traceless, out)
            return out.reshape(Wa.shape[:-2])
        D = Wa - self.sigma(Wa)
        D *= 0.5
        if self.traceless:  # W - P = D + (Tr(W - D) / n) I
            tr = (trace(Wa) - trace(D)) / self.n  # a member's bits in any batch
            idx = np.arange(self.n)
            D[..., idx, idx] += tr[..., None]
        return np.sqrt(_sum_of_squares(D))

    def bracket(self, A: Array, X: Array) -> Array:
        return A @ X - X @ A

    def to_matrix(self, W: Array) -> Array:
        """The matrices themselves.

        Parameters
        ----------
        W : ndarray, shape (*batch, n, n)
            Elements of ``V`` or of its normalizer.
        """
        return np.asarray(W)

    def from_matrix(self, M: Array) -> Array:
        """The matrices themselves (not projected).

        Parameters
        ----------
        M : ndarray, shape (*batch, n, n)
            Matrices.
        """
        return np.asarray(M)

    def dagger(self, Y: Array) -> Array:
        """Conjugate transpose over the last two axes.

        Parameters
        ----------
        Y : ndarray, shape (*batch, n, n)
            Matrices.

        Returns
        -------
        ndarray, shape (*batch, n, n)
        """
        return np.conj(np.swapaxes(Y, -1, -2))

    def bracket_and_triple(self, B: Array, X: Array) -> tuple[Array, Array]:
        P = B @ X
        if self.structured:
            C = P + self.sigma(P)
        else:
            C = P - X @ B
        return C, P @ B

    # ---- basis generated from sigma --------------------------------------------------------
    def _basis_matrix(self) -> sp.csr_array:
        """Orthonormal basis read off the signed permutation ``sigma`` of real coordinates.

        Applying ``sigma`` to the element whose real coordinates are ``1, 2, ..., m`` gives
        ``sigma`` as ``(S v)_a = s_a v_{p(a)}``. Each orbit ``{a, p(a)}`` contributes
        ``(e_{p(a)} + s_a e_a)/sqrt 2`` (or ``e_a`` when ``p(a) = a`` and ``s_a = +1``).
        """
        m = self.n * self.n * (2 if self.is_complex else 1)
        # the probes and the lists of the basis's entries (Python objects): ~ 100 bytes each
        _require_memory(8.0 * m, 12.0, f"the basis of {self.name}")
        probe = self._unflatten(np.arange(1, m + 1, dtype=np.float64))
        image = self._flatten(self.sigma(probe))
        perm = np.rint(np.abs(image)).astype(np.int64) - 1
        sign = np.sign(image)
        rows: list[int] = []
        cols: list[int] = []
        vals: list[float] = []
        seen = np.zeros(m, dtype=bool)
        diag_imag: list[int] = []  # coordinates of i*E_kk, replaced for traceless spaces
        diag_real: list[int] = []
        nn = self.n * self.n
        diag_positions = {k * self.n + k for k in range(self.n)}
        k_row = 0
        for a in range(m):
            if seen[a]:
                continue
            b = int(perm[a])
            seen[a] = seen[b] = True
            if b == a:
                if sign[a] > 0:
                    if self.traceless and (a % nn) in diag_positions:
                        (diag_imag if a >= nn else diag_real).append(a)
                        continue
                    rows.append(k_row)
                    cols.append(a)
                    vals.append(1.0)
                    k_row += 1
                continue
            rows += [k_row, k_row]
            cols += [b, a]
            vals += [1.0 / np.sqrt(2.0), float(sign[a]) / np.sqrt(2.0)]
            k_row += 1
        for diag in (diag_real, diag_imag):
            # traceless diagonal: orthonormal (Helmert) basis of {d : sum d = 0}
            for k in range(1, len(diag)):
                norm = np.sqrt(k * (k + 1.0))
                for j in range(k):
                    rows.append(k_row)
                    cols.append(diag[j])
                    vals.append(1.0 / norm)
                rows.append(k_row)
                cols.append(diag[k])
                vals.append(-k / norm)
                k_row += 1
        import scipy.sparse as sp

        return sp.csr_array((vals, (rows, cols)), shape=(k_row, m))

    def trace_powers(self, W: Array) -> Array:
        r"""``Tr(W^k)`` for ``k = 1..n``, shape ``(*batch, n)``; Casimirs of every flow."""
        out = []
        P = W
        for _ in range(self.n):
            out.append(trace(P))
            P = P @ W
        return np.stack(out, axis=-1)

    def casimir_scale(self, W0: Array) -> Array:
        """Natural size of each Casimir component at ``W0`` (to turn drifts into relative ones)."""
        norm = np.maximum(self.norm(W0), np.finfo(float).tiny)
        if self.casimirs_are_eigenvalues:
            return np.broadcast_to(norm[..., None], (*norm.shape, self.n))
        k = np.arange(1, self.n + 1)
        return norm[..., None] ** k

    #: Whether :meth:`casimirs` returns eigenvalues (normal matrices) or trace powers.
    casimirs_are_eigenvalues: bool = True


#: Entries of one member from which :meth:`MatrixAlgebra.distance` runs compiled (below, NumPy:
#: no compilation for small states). A member's size, not the batch's: a state gets the same
#: bits in any batch (a resumed run's first row alone, :mod:`isoflow._reductions`).
_COMPILED_DISTANCE_SIZE = 1 << 16


def _sum_of_squares(M: Array) -> Array:
    r""":math:`\sum_{ij} |M_{ij}|^2` over the last two axes, the same bits for a member in any
    batch (:mod:`isoflow._reductions`; temporaries of bounded size)."""
    if M.dtype.kind not in "fc":
        M = M.astype(np.float64)
    return sum_of_squares(M)


#: States below this many bytes are not checked against the available memory.
_MEMORY_CHECK_BYTES = 64 * 2**20


def _require_memory(state_bytes: float, peak_states: float, what: str) -> None:
    """A :class:`~isoflow.ParameterError` for a state too large for this machine's memory
    (checked from :data:`_MEMORY_CHECK_BYTES` on), instead of numpy's ``MemoryError``."""
    if state_bytes < _MEMORY_CHECK_BYTES:
        return
    from ..models._checks import require_memory

    require_memory(state_bytes, peak_states, what)
