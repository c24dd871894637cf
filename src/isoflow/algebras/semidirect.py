r"""Two fields, one structure: the semidirect products :math:`\mathfrak g \ltimes \mathfrak g^*`.

The state of a Lie–Poisson system on :math:`(\mathfrak g \ltimes \mathfrak g^*)^*` is a pair: an
*advected* field :math:`\Theta` (the magnetic potential of MHD, the direction of gravity
:math:`\Gamma` of a heavy top) and a *momentum* :math:`W` (the vorticity, the angular momentum
:math:`M`). With the ad-invariant trace pairing of :math:`\mathfrak g` (so that
:math:`\mathfrak g^* \cong \mathfrak g`) the algebra is that of the **dual numbers** over
:math:`\mathfrak g`,

.. math::

    \mathfrak g_\varepsilon = \{X_0 + \varepsilon X_1\}, \qquad \varepsilon^2 = 0, \qquad
    [A_0 + \varepsilon A_1, X_0 + \varepsilon X_1]
        = [A_0, X_0] + \varepsilon\,([A_0, X_1] + [A_1, X_0]),

and a state is :math:`M = \Theta + \varepsilon W`. The flow of a Hamiltonian
:math:`H(\Theta, W)` is the isospectral flow :math:`\dot M = [B, M]` with
:math:`B = P + \varepsilon J`, :math:`P = (\partial H/\partial W)^\dagger`,
:math:`J = (\partial H/\partial\Theta)^\dagger`:

.. math::

    \dot\Theta = [P, \Theta], \qquad \dot W = [P, W] + [J, \Theta].

So every isospectral method applies unchanged, and IsoMP needs no exponential: its step is the
conjugation :math:`M_{k+1} = C M_k C^{-1}` by the dual-number Cayley factor
:math:`C = (I + \tfrac h2 B)(I - \tfrac h2 B)^{-1}`, which keeps
:math:`\operatorname{Tr}(M^{k+1}) = \operatorname{Tr}(\Theta^{k+1})
+ \varepsilon\,(k+1)\operatorname{Tr}(W\Theta^k)`: both Casimir families exactly (to rounding).
``docs/theory/semidirect.rst`` derives all of this and checks it against Modin and Roop.

Array layout (one convention for states and ``B``)
--------------------------------------------------
A pair is an array of shape ``(*batch, 2, *field_shape)``: index ``0`` holds the
:math:`\varepsilon^0` part, index ``1`` the :math:`\varepsilon` part. For a state that is
``(Theta, W)`` (or ``(Gamma, M)``), for ``B`` it is ``(P, J)``. The products are those of dual
numbers: :math:`(A B)_0 = A_0 B_0`, :math:`(A B)_1 = A_0 B_1 + A_1 B_0` (three products of
fields for one of pairs).

Pairing and gradients. :meth:`~isoflow.algebras.Algebra.inner` is the plain Frobenius (Euclidean)
pairing of the stacked arrays: it is what norms, coordinates and gradients refer to. The
Lie–Poisson pairing of :math:`\mathfrak g_\varepsilon` with itself is the
:math:`\varepsilon`-part of the trace pairing, which pairs field ``0`` of one argument with
field ``1`` of the other; the :meth:`dagger` of a pair therefore swaps the fields:
:meth:`IsospectralProblem.from_hamiltonian <isoflow.IsospectralProblem.from_hamiltonian>` with
the field-wise gradient :math:`(\partial H/\partial\Theta, \partial H/\partial W)` gives
:math:`B = ((\partial H/\partial W)^\dagger, (\partial H/\partial\Theta)^\dagger)`.

Spaces
------
:func:`semidirect` (:class:`SemidirectProduct`): ``so(n)``, ``u(n)``, ``su(n)`` pairs,
``(2, n, n)``; :func:`se3_vectors` (:class:`SE3Vectors`): the heavy top's
:math:`\mathfrak{so}(3) \ltimes \mathbb{R}^3 = \mathfrak{se}(3)` in vectors, ``(2, 3)``.
"""

from __future__ import annotations

from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    import scipy.sparse as sp

from .._errors import NotInSpaceError, ParameterError, ShapeError
from ._base import Algebra, MatrixAlgebra
from ._vectors import ParticleVectors
from .orthogonal import SpecialOrthogonal
from .spin import cross, dot, hat, vee
from .stacked import Stacked
from .unitary import Unitary

__all__ = ["SE3Vectors", "SemidirectProduct", "se3_vectors", "semidirect"]

Array = NDArray[Any]


class _Pairs:
    """What both pair spaces share: field names, building and splitting pairs, the dagger
    that swaps the fields, and validation that names the field at fault."""

    #: Names of the two fields of a state, in array order (``0``: advected, ``1``: momentum).
    fields: tuple[str, str]
    #: Shape of one field.
    field_shape: tuple[int, ...]
    name: str
    shape: tuple[int, ...]
    dtype: np.dtype[Any]

    def _field_dagger(self, G: Array) -> Array:  # pragma: no cover - abstract
        raise NotImplementedError

    def _field_distance(self, F: Array) -> Array:  # pragma: no cover - abstract
        raise NotImplementedError

    def pair(self, advected: ArrayLike, momentum: ArrayLike) -> Array:
        """The pair ``(advected, momentum)`` (e.g. ``(Theta, W)``) as one array of :attr:`shape`.

        Both fields may carry the same leading ensemble axes.

        Raises
        ------
        ShapeError
            The two fields differ in shape, or are not fields of this space.
        """
        a, m = np.asarray(advected), np.asarray(momentum)
        first, second = self.fields
        if a.shape != m.shape:
            raise ShapeError(
                f"the fields of {self.name} must have one shape: {first} has {a.shape}, "
                f"{second} has {m.shape}"
            )
        k = len(self.field_shape)
        if a.shape[a.ndim - k :] != self.field_shape or a.ndim < k:
            raise ShapeError(
                f"the fields of {self.name} have shape (*batch, "
                f"{', '.join(map(str, self.field_shape))}), got {a.shape}"
            )
        dt = np.result_type(a, m, self.dtype)
        return np.stack([a, m], axis=a.ndim - k).astype(dt, copy=False)

    def split(self, Y: ArrayLike) -> tuple[Array, Array]:
        """The two fields ``(advected, momentum)`` of pairs ``Y`` (views, no copy)."""
        Ya = np.asarray(Y)
        k = len(self.field_shape)
        if Ya.ndim < k + 1 or Ya.shape[Ya.ndim - k - 1 :] != self.shape:
            raise ShapeError(
                f"pairs of {self.name} have shape (*batch, {', '.join(map(str, self.shape))}), "
                f"got {Ya.shape}"
            )
        core: tuple[Any, ...] = (slice(None),) * k
        return Ya[(Ellipsis, 0, *core)], Ya[(Ellipsis, 1, *core)]

    def dagger(self, G: Array) -> Array:
        r"""The map from gradients to ``B``: the fields swapped, each daggered.

        For the field-wise gradient :math:`G = (\partial H/\partial\Theta, \partial
        H/\partial W)` it returns :math:`B = ((\partial H/\partial W)^\dagger, (\partial
        H/\partial\Theta)^\dagger)`, the gradient in the Lie–Poisson pairing (module
        docstring).
        """
        g0, g1 = self.split(G)
        return self.pair(self._field_dagger(g1), self._field_dagger(g0))

    def validate(
        self, W: ArrayLike, what: str = "state", rtol: float = 1e-10, atol: float = 1e-12,
        *, project: bool = True,
    ) -> Array:  # fmt: skip
        """:meth:`Algebra.validate`, with a state outside the space blamed on its field.

        Parameters
        ----------
        W : array_like, shape (*batch, 2, *field_shape)
            The pair(s) to check.
        what : str
            Names ``W`` in the error messages (default ``"state"``).
        rtol, atol : float
            Relative and absolute tolerance of the distance to the space (defaults ``1e-10``
            and ``1e-12``).
        project : bool
            Whether to return the projection onto the space (default) or the checked values.

        Returns
        -------
        ndarray, shape (*batch, 2, *field_shape)

        Raises
        ------
        NotInSpaceError
            A pair too far from the space; the message names the field farthest from its
            space.
        DtypeError, ShapeError, NonFiniteError
            As :meth:`Algebra.validate`.
        """
        try:
            return super().validate(W, what, rtol, atol, project=project)  # type: ignore[misc, no-any-return]
        except NotInSpaceError as exc:
            fields = self.split(np.asarray(W).astype(self.dtype))
            dists = [float(np.max(self._field_distance(F))) for F in fields]
            i = int(np.argmax(dists))
            raise NotInSpaceError(
                f"{what} is not in {self.name}: its field {self.fields[i]} (index {i}) is "
                f"{dists[i]:.3e} away from its space (tolerance {exc.tolerance:.3e})",
                distance=exc.distance,
                tolerance=exc.tolerance,
            ) from None


def _dual_matmul(A: Array, B: Array) -> Array:
    """Products of dual-number matrices ``(..., 2, n, n)``: ``(A0 B0, A0 B1 + A1 B0)``."""
    A0, A1 = A[..., 0, :, :], A[..., 1, :, :]
    B0, B1 = B[..., 0, :, :], B[..., 1, :, :]
    return np.stack([A0 @ B0, A0 @ B1 + A1 @ B0], axis=-3)


class SemidirectProduct(_Pairs, Algebra):
    r""":math:`\mathfrak g \ltimes \mathfrak g^*` for ``g = so(n), u(n), su(n)``: pairs of
    matrices ``(Theta, W)``, shape ``(2, n, n)``.

    * ``bracket``, ``bracket_and_triple``: the dual-number products of the module docstring
      (``[B, X]`` and ``B X B``: six ``n x n`` products);
    * ``project``: the base projection on each field; the normalizer and the stage space are
      the pairs over the base's (``u(n)`` for ``su(n)``);
    * ``casimirs``: the ``n`` eigenvalues :math:`\lambda_i` of :math:`i\Theta` (ascending),
      then the cross family :math:`c_k = \operatorname{Tr}\big(iW\,(i\Theta/\rho)^k\big)`,
      ``k = 0 .. n-1``, :math:`\rho = \max_i|\lambda_i|` (a Casimir itself; it keeps the
      powers in range), from one eigendecomposition of :math:`i\Theta`
      (:math:`c_k = \sum_i d_i(\lambda_i/\rho)^k`, :math:`d_i = (U^\dagger iW U)_{ii}`); drifts
      are relative to :math:`\|\Theta_0\|` and to the pair's norm :math:`\|(\Theta_0, W_0)\|`;
    * ``to_matrix``: the block matrices :math:`\begin{pmatrix}\Theta & W\\ 0 & \Theta
      \end{pmatrix}` (a Lie algebra homomorphism), ``(2n, 2n)``;
    * ``inner``: Frobenius over both fields; ``dagger`` swaps the fields (module docstring).

    Parameters
    ----------
    base : SpecialOrthogonal or Unitary
        ``so(n)``, ``u(n)`` or ``su(n)``.
    """

    fields = ("Theta", "W")

    def __init__(self, base: MatrixAlgebra) -> None:
        if not isinstance(base, (SpecialOrthogonal, Unitary)):
            raise ParameterError(f"semidirect: the base must be so(n), u(n) or su(n), got {base!r}")
        self.base = base
        self.field_shape = base.shape
        self.shape = (2, *base.shape)
        self.dtype = base.dtype
        self.name = f"{base.name} x| {base.name}*"

    @cached_property
    def _copies(self) -> Stacked:
        """The two fields as a vector space (projection, basis, coordinates)."""
        return Stacked(self.base, 2)

    @property
    def normalizer(self) -> SemidirectProduct:
        return SemidirectProduct(self.base.normalizer)  # type: ignore[arg-type]

    @property
    def stage_algebra(self) -> SemidirectProduct:
        return SemidirectProduct(self.base.stage_algebra)  # type: ignore[arg-type]

    @property
    def dim(self) -> int:
        return 2 * self.base.dim

    def project(self, W: Array) -> Array:
        """The base's orthogonal projection on each field.

        Parameters
        ----------
        W : ndarray, shape (*batch, 2, n, n)
            Pairs of matrices.

        Returns
        -------
        ndarray, shape (*batch, 2, n, n)
        """
        return self._copies.project(W)

    def _field_distance(self, F: Array) -> Array:
        return self.base.distance(F)

    def _field_dagger(self, G: Array) -> Array:
        return self.base.dagger(G)

    def bracket(self, A: Array, X: Array) -> Array:
        r"""``[A, X] = ([A0, X0], [A0, X1] + [A1, X0])``."""
        return _dual_matmul(A, X) - _dual_matmul(X, A)

    def bracket_and_triple(self, B: Array, X: Array) -> tuple[Array, Array]:
        r"""``([B, X], B X B)`` with ``P = B X`` (three products), ``[B, X] = P + sigma(P)``
        field by field, ``B X B = P B`` (three more)."""
        P = _dual_matmul(B, X)
        return P + self.base.sigma(P), _dual_matmul(P, B)

    def casimirs(self, W: Array) -> Array:
        """``(*batch, 2n)``: the spectrum of ``i Theta``, then the cross family (class
        docstring).

        Parameters
        ----------
        W : ndarray, shape (*batch, 2, n, n)
            Pairs ``(Theta, W)``.

        Returns
        -------
        ndarray, shape (*batch, 2n)
        """
        from .._eig import eigh_diagonal

        theta, w = self.split(np.asarray(W))
        lam, d = eigh_diagonal(1j * theta, 1j * w)
        rho = np.max(np.abs(lam), axis=-1, keepdims=True)
        x = lam / np.where(rho > 0, rho, 1.0)
        powers = x[..., None, :] ** np.arange(self.base.n)[:, None]  # (*batch, k, i); 0^0 = 1
        return np.concatenate([lam, np.einsum("...ki,...i->...k", powers, d)], axis=-1)

    def casimir_scale(self, W0: Array) -> Array:
        """``||Theta_0||`` for the spectrum, ``||(Theta_0, W_0)||`` for the cross family.

        Parameters
        ----------
        W0 : ndarray, shape (*batch, 2, n, n)
            The initial pairs.

        Returns
        -------
        ndarray, shape (*batch, 2n)
            Each at least the smallest positive float.
        """
        theta, _ = self.split(np.asarray(W0))
        tiny = np.finfo(float).tiny
        n = self.base.n
        s0 = np.maximum(self.base.norm(theta), tiny)[..., None]
        s1 = np.maximum(self.norm(W0), tiny)[..., None]
        return np.concatenate([np.repeat(s0, n, -1), np.repeat(s1, n, -1)], axis=-1)

    def _basis_matrix(self) -> sp.csr_array:
        return self._copies._basis_matrix()

    def to_coords(self, W: Array) -> Array:
        return self._copies.to_coords(W)

    def from_coords(self, coords: ArrayLike) -> Array:
        """The pairs with the given coordinates (those of the two fields, one after the other).

        Parameters
        ----------
        coords : array_like, shape (*batch, dim)
            Coordinates in the orthonormal basis, ``dim = 2 base.dim``.

        Returns
        -------
        ndarray, shape (*batch, 2, n, n)
        """
        return self._copies.from_coords(coords)

    def to_matrix(self, W: Array) -> Array:
        r"""The block matrices :math:`\begin{pmatrix}X_0 & X_1\\ 0 & X_0\end{pmatrix}`,
        ``(*batch, 2n, 2n)``: their products are the dual-number products.

        Parameters
        ----------
        W : ndarray, shape (*batch, 2, n, n)
            Pairs ``(X_0, X_1)`` (states or values of ``B``).
        """
        X0, X1 = self.split(np.asarray(W))
        zero = np.zeros_like(X0)
        top = np.concatenate([X0, X1], axis=-1)
        return np.concatenate([top, np.concatenate([zero, X0], axis=-1)], axis=-2)

    def from_matrix(self, M: Array) -> Array:
        """The pair of a block matrix (the mean of the two diagonal blocks, the upper right
        block; not projected).

        Parameters
        ----------
        M : ndarray, shape (*batch, 2n, 2n)
            Block matrices.

        Returns
        -------
        ndarray, shape (*batch, 2, n, n)
        """
        n = self.base.n
        Ma = np.asarray(M)
        X0 = 0.5 * (Ma[..., :n, :n] + Ma[..., n:, n:])
        return self.pair(X0, Ma[..., :n, n:])

    def __repr__(self) -> str:
        return f"<algebra {self.name} (pairs (Theta, W), dual numbers over {self.base.name})>"


class SE3Vectors(_Pairs, ParticleVectors):
    r""":math:`\mathfrak{so}(3) \ltimes \mathbb{R}^3 = \mathfrak{se}(3)` in vectors: the heavy
    top's pairs ``(Gamma, M)``, shape ``(2, 3)``.

    The compact form of :class:`SemidirectProduct` over :math:`(\mathbb{R}^3, \times)`
    (:class:`~isoflow.algebras.SpinVectors`): the hat map takes the dual products to

    * ``bracket(B, X) = (b0 x x0, b0 x x1 + b1 x x0)``;
    * ``bracket_and_triple``: also :math:`\hat b\hat x\hat b = -(b\cdot x)\,\hat b` and its
      polarization :math:`\hat a\hat x\hat c + \hat c\hat x\hat a = -(a\cdot x)\,\hat c
      - (c\cdot x)\,\hat a`: ``T = (-(b0.x0) b0, -(b0.x1) b0 - (b1.x0) b0 - (b0.x0) b1)``;
    * ``casimirs``: :math:`|\Gamma|^2` and :math:`M\cdot\Gamma`, relative to
      :math:`|\Gamma_0|^2` and :math:`|\Gamma_0|\,|(\Gamma_0, M_0)|`;
    * ``inner``: the Euclidean dot product of the six numbers (half the Frobenius pairing of
      the hat matrices); ``dagger(G) = -(G_1, G_0)``, so ``from_hamiltonian`` with the
      Euclidean gradient gives :math:`B = -(\partial H/\partial M, \partial H/\partial\Gamma)`
      and the heavy top equations :math:`\dot\Gamma = \Gamma\times\Omega`,
      :math:`\dot M = M \times \Omega + \Gamma \times \partial H/\partial\Gamma`,
      :math:`\Omega = \partial H/\partial M` (:func:`isoflow.models.heavy_top`).

    Row ``0`` is :math:`\Gamma`, row ``1`` is :math:`M`; every real ``(2, 3)`` array is an
    element; leading axes form an ensemble of tops.
    """

    fields = ("Gamma", "M")
    name_template = "(R^3, x) x| R^3"
    field_shape = (3,)

    def __init__(self) -> None:
        super().__init__(2)

    def _field_distance(self, F: Array) -> Array:
        return np.zeros(F.shape[:-1])

    def _field_dagger(self, G: Array) -> Array:
        return -np.asarray(G)

    def bracket(self, A: Array, X: Array) -> Array:
        """``(a0 x x0, a0 x x1 + a1 x x0)``.

        Parameters
        ----------
        A, X : ndarray, shape (*batch, 2, 3)
            Pairs of vectors.

        Returns
        -------
        ndarray, shape (*batch, 2, 3)
        """
        a0, a1 = self.split(A)
        x0, x1 = self.split(X)
        return self.pair(cross(a0, x0), cross(a0, x1) + cross(a1, x0))

    def bracket_and_triple(self, B: Array, X: Array) -> tuple[Array, Array]:
        """The bracket and the dual triple product (class docstring).

        Parameters
        ----------
        B, X : ndarray, shape (*batch, 2, 3)
            Pairs of vectors: a value of ``B`` and a state.

        Returns
        -------
        (ndarray, ndarray), each of shape (*batch, 2, 3)
        """
        b0, b1 = self.split(B)
        x0, x1 = self.split(X)
        bx0 = dot(b0, x0)[..., None]
        T = self.pair(-bx0 * b0, -(dot(b0, x1) + dot(b1, x0))[..., None] * b0 - bx0 * b1)
        return self.bracket(B, X), T

    def casimirs(self, W: Array) -> Array:
        r"""``(*batch, 2)``: :math:`|\Gamma|^2` and :math:`M\cdot\Gamma`.

        Parameters
        ----------
        W : ndarray, shape (*batch, 2, 3)
            Pairs ``(Gamma, M)``.

        Returns
        -------
        ndarray, shape (*batch, 2)
        """
        g, m = self.split(np.asarray(W))
        return np.stack([dot(g, g), dot(m, g)], axis=-1)

    def casimir_scale(self, W0: Array) -> Array:
        r""":math:`|\Gamma_0|^2` and :math:`|\Gamma_0|\,|(\Gamma_0, M_0)|` (at least ``tiny``).

        Parameters
        ----------
        W0 : ndarray, shape (*batch, 2, 3)
            The initial pairs ``(Gamma_0, M_0)``.

        Returns
        -------
        ndarray, shape (*batch, 2)
        """
        g, _ = self.split(np.asarray(W0))
        ng = np.sqrt(dot(g, g))
        tiny = np.finfo(float).tiny
        return np.maximum(np.stack([ng * ng, ng * self.norm(W0)], axis=-1), tiny)

    def to_matrix(self, W: Array) -> Array:
        r"""The ``6 x 6`` block matrices :math:`\begin{pmatrix}\hat\Gamma & \hat M\\ 0 &
        \hat\Gamma\end{pmatrix}`.

        Parameters
        ----------
        W : ndarray, shape (*batch, 2, 3)
            Pairs ``(Gamma, M)`` (or values of ``B``).

        Returns
        -------
        ndarray, shape (*batch, 6, 6)
        """
        g, m = self.split(np.asarray(W))
        G, M = hat(g), hat(m)
        top = np.concatenate([G, M], axis=-1)
        return np.concatenate([top, np.concatenate([np.zeros_like(G), G], axis=-1)], axis=-2)

    def from_matrix(self, M: Array) -> Array:
        """The pair of a block matrix (vectors of the skew parts, the diagonal blocks
        averaged).

        Parameters
        ----------
        M : ndarray, shape (*batch, 6, 6)
            Block matrices.

        Returns
        -------
        ndarray, shape (*batch, 2, 3)
        """
        Ma = np.asarray(M)
        g = vee(0.5 * (Ma[..., :3, :3] + Ma[..., 3:, 3:]))
        return self.pair(g, vee(Ma[..., :3, 3:]))

    def __repr__(self) -> str:
        return f"<algebra {self.name} ~ se(3), pairs (Gamma, M)>"


def semidirect(base: MatrixAlgebra) -> SemidirectProduct:
    r"""The pairs ``(Theta, W)`` of :math:`\mathfrak g \ltimes \mathfrak g^*` over
    ``base = so(n), u(n), su(n)``, shape ``(2, n, n)`` (see the module docstring).

    Raises
    ------
    ParameterError
        Another base space.

    Examples
    --------
    The Lie–Poisson flow of :math:`H = \frac12\|W\|^2 + \operatorname{Tr}(K^T\Theta)` on
    :math:`\mathfrak{so}(3)\ltimes\mathfrak{so}(3)^*`, from the field-wise gradient:

    >>> import numpy as np, isoflow as iso
    >>> alg = iso.algebras.semidirect(iso.algebras.so(3))
    >>> K = iso.algebras.so(3).random(seed=1)
    >>> def H(Y):
    ...     theta, w = alg.split(Y)
    ...     return 0.5 * np.sum(w * w, axis=(-2, -1)) + np.sum(K * theta, axis=(-2, -1))
    >>> def grad(Y):
    ...     theta, w = alg.split(Y)
    ...     return alg.pair(np.broadcast_to(K, w.shape), w)
    >>> prob = iso.IsospectralProblem.from_hamiltonian(alg, H, grad)
    >>> y0 = alg.pair(iso.algebras.so(3).random(seed=2), iso.algebras.so(3).random(seed=3))
    >>> sol = iso.solve(prob, iso.IsoMP(), y0, dt=0.05, n_steps=100)
    >>> bool(sol.diagnostics.casimir_drift < 1e-12)
    True
    """
    return SemidirectProduct(base)


def se3_vectors() -> SE3Vectors:
    r"""The heavy top's space :math:`\mathfrak{so}(3)\ltimes\mathbb{R}^3` in vectors: pairs
    ``(Gamma, M)``, shape ``(2, 3)`` (see :class:`SE3Vectors`)."""
    return SE3Vectors()
