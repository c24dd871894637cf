r"""Reproducible noise: Brownian increments keyed by (seed, member, step), and transport noise.

Increments
----------
:func:`standard_normals` and :func:`brownian_increments` give the normals and increments of the
steps ``k0 + 1 .. k0 + nsteps`` of ensemble members, one array ``(nsteps, members, count)`` per
call. They come from numpy's counter-based bit generator :class:`numpy.random.Philox`
(Philox4x64-10, four 64-bit words a block) with the key ``(seed, stream)``. Member ``m`` owns
``b = ceil(count / 4)`` blocks of each step: its raw words of step ``k`` are the first ``4 b``
that ``Philox(key=(seed, stream), counter=m b + 2**64 k)`` returns (the counter's low word
numbers the member's blocks, the next word the step), of which the first ``count`` are used.
Each word becomes the uniform ``((w >> 12) + 1/2) 2**-52``, a midpoint of the grid of ``2**52``
cells of ``(0, 1)``: exact in double precision, symmetric about 1/2, never 0 or 1 (with 53 bits,
``2**53 - 1/2`` would round up to ``2**53`` and the top word give 1), and that its normal
quantile (:func:`scipy.special.ndtri`), finite (at most 8.21 in size). A step's normals are
therefore a function of ``(seed, stream, member, step)`` alone: a run, its resume after a kill,
an ensemble split into the tasks of a sweep (give the members their ids in the sweep) and any
number of threads draw exactly the same increments, bit for bit. Members with consecutive ids have
consecutive counters, so one bit generator draws a step of a whole run of them at once (the
cost is the raw draws and the quantiles, not one generator per member). ``stream`` separates
independent uses of one seed (transport noise is stream ``0``; a stochastic forcing takes
another).

Large steps: truncated increments
---------------------------------
An implicit step with an unbounded Gaussian increment has, with positive probability, no
solution near the state (the fixed-point map stops contracting once :math:`|\Delta\beta|` is
large). Following Milstein, Repin and Tretyakov (*SIAM J. Numer. Anal.* 40 (2002) 1583-1604),
the stochastic midpoint draws :math:`\Delta\beta = \sqrt h\,\zeta_h` with the normal ``zeta``
clipped to :math:`\pm A_h`, :math:`A_h = \sqrt{2 k |\ln h|}` (:func:`truncation_level`; a floor
of :math:`\sqrt{2k}` for :math:`h > 1/e`). Clipping changes the second moment by
:math:`O(h^k)`, so ``k = 2`` (the default) keeps the strong order 1/2 and the weak order 1.
Without truncation (``truncation=None``) a step whose solve diverges fails its member with the
driver's stopping rule (``diverged``), as any failed solve does: never a hang.

Transport noise
---------------
:class:`TransportNoise` is the noise of a stochastic Lie–Poisson system in Stratonovich form,

.. math::

    dW = [B(W), W]\,dt + \sum_{i=1}^m [B_i(W), W] \circ d\beta_i(t),

with constant fields :math:`B_i = \Xi_i` (the gradients of linear noise Hamiltonians
:math:`H_i(W) = \langle \Xi_i^\dagger, W\rangle`), state-dependent fields (a Python function,
NumPy path only), and on particle spaces isotropic *site noise* (three independent Brownian
motions per particle, amplitude :math:`\sigma_p`: the thermal field of a spin). Integrate it with
:class:`isoflow.StochasticIsoMP` (``docs/theory/stochastic.rst``).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._errors import InvalidBError, ParameterError, ShapeError

if TYPE_CHECKING:
    from .algebras import Algebra

__all__ = [
    "TRANSPORT_STREAM",
    "TransportNoise",
    "brownian_increments",
    "check_seed",
    "standard_normals",
    "truncation_level",
]

Array = NDArray[Any]

#: The Philox stream of transport noise (other uses of a seed take other streams).
TRANSPORT_STREAM = 0
#: Largest seed (the first word of the Philox key).
_SEED_MAX = 2**64 - 1
#: A 52-bit integer plus 1/2 times this is a double in (0, 1), exactly.
_TWO_TO_MINUS_52 = 2.0**-52
#: Members whose ids are at most this many raw words apart are drawn by one positioning of the
#: bit generator (a positioning costs about as much as a few hundred words).
_BRIDGE_WORDS = 256


def check_seed(seed: Any, what: str = "seed") -> int:
    """``seed`` as an int in ``[0, 2**64)``, else a one-line :class:`ParameterError`.

    Noise needs an explicit seed: ``None`` is refused (a run that cannot be repeated is not
    what a stochastic integrator of this library produces).
    """
    if seed is None:
        raise ParameterError(f"{what} is required for noise (an integer >= 0): the increments "
                             "are keyed by it, so that runs and resumes repeat them")  # fmt: skip
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ParameterError(f"{what} must be an integer >= 0, got {seed!r}")
    if not 0 <= int(seed) <= _SEED_MAX:
        raise ParameterError(f"{what} must be in [0, 2**64), got {seed!r}")
    return int(seed)


def _members(members: ArrayLike) -> NDArray[np.int64]:
    m = np.ascontiguousarray(np.asarray(members, dtype=np.int64).reshape(-1))
    return m


def _counts(k0: int, nsteps: int, count: int) -> None:
    for name, v in (("k0", k0), ("nsteps", nsteps), ("count", count)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise ParameterError(f"{name} must be an integer >= 0, got {v!r}")


def standard_normals(
    seed: int, members: ArrayLike, k0: int, nsteps: int, count: int, *,
    stream: int = TRANSPORT_STREAM, clip: float | None = None,
) -> Array:  # fmt: skip
    """Standard normals ``(nsteps, len(members), count)`` of the steps ``k0 + 1 .. k0 +
    nsteps`` (see the module docstring); members ``< 0`` (padding) get zeros; ``clip`` clips
    them to ``[-clip, clip]``.

    Raises
    ------
    ParameterError
        A seed, stream, step or count that is not an integer ``>= 0``; a member id too large
        for the counter (``(id + 1) ceil(count / 4) >= 2**64``).

    Examples
    --------
    >>> import numpy as np
    >>> from isoflow import noise
    >>> a = noise.standard_normals(7, [0, 1], 0, 10, 3)
    >>> b = noise.standard_normals(7, [1], 4, 6, 3)      # member 1, steps 5..10
    >>> bool(np.array_equal(a[4:, 1], b[:, 0]))
    True
    """
    seed = check_seed(seed)
    _counts(k0, nsteps, count)
    stream = check_seed(stream, "stream")
    ids = _members(members)
    blocks = -(-count // 4)
    if ids.size and int(ids.max()) >= (_SEED_MAX + 1) // max(blocks, 1) - 1:
        raise ParameterError(
            f"member id {int(ids.max())} is too large for {count} normals a step (the "
            "counter holds (id + 1) * ceil(count / 4) < 2**64)"
        )
    out = np.empty((nsteps, ids.size, count))
    if out.size:
        for s, raw in enumerate(_raw_words(seed, stream, ids, int(k0), nsteps, blocks)):
            _normals_from_words(raw[:, :count], out[s], clip)  # a step at a time: in cache
        padding = ids < 0
        if padding.any():
            out[:, padding] = 0.0
    return out


def _spans(ids: NDArray[np.int64], words: int) -> tuple[list[tuple[int, int]], NDArray[np.intp]]:
    """The spans of member ids one bit generator draws at once, and where each valid id's words
    sit in their concatenation.

    Returns ``(spans, rows)``: ``spans`` lists ``(first id, length)``; the words of ``ids[j] >=
    0`` are row ``rows[i]`` of the concatenated spans' ``(sum of lengths, words)`` draws, ``i``
    counting the valid ids. Ids closer than :data:`_BRIDGE_WORDS` words share a span (drawing
    the members between is cheaper than positioning the generator again); the draws do not
    depend on the spans.
    """
    unique, inverse = np.unique(ids[ids >= 0], return_inverse=True)
    if unique.size == 0:
        return [], np.zeros(0, dtype=np.intp)
    split = np.flatnonzero((np.diff(unique) - 1) * words > _BRIDGE_WORDS) + 1
    starts = np.concatenate([[0], split])
    stops = np.concatenate([split, [unique.size]])
    first = unique[starts]
    lengths = unique[stops - 1] - first + 1
    offsets = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    span_of = np.repeat(np.arange(starts.size), stops - starts)
    rows = offsets[span_of] + unique - first[span_of]
    spans = [(int(f), int(n)) for f, n in zip(first, lengths, strict=True)]
    return spans, rows[inverse]


def _raw_words(
    seed: int, stream: int, ids: NDArray[np.int64], k0: int, nsteps: int, blocks: int
) -> Iterator[NDArray[np.uint64]]:
    """The raw words ``(len(ids), 4 blocks)`` of each step ``k0 + 1 .. k0 + nsteps`` in turn,
    in one buffer (the rows of ids ``< 0`` are left unset): one positioning of one bit
    generator per step and span (:func:`_spans`)."""
    words = 4 * blocks
    raw = np.empty((ids.size, words), dtype=np.uint64)
    # consecutive ids (an ensemble 0..M-1, one member): the draws land in their rows directly
    direct = bool(ids[0] >= 0 and np.all(np.diff(ids) == 1))
    if direct:
        spans, rows = [(int(ids[0]), int(ids.size))], None
        drawn = raw
    else:
        spans, rows = _spans(ids, words)
        valid = ids >= 0
        drawn = np.empty((sum(n for _, n in spans), words), dtype=np.uint64)
    bitgen = np.random.Philox(key=np.array([seed, stream], dtype=np.uint64))
    state = bitgen.state
    for s in range(nsteps):
        step = (k0 + 1 + s) << 64
        row = 0
        for first, length in spans:
            state["state"]["counter"] = _counter_words(first * blocks + step)
            state["buffer_pos"] = 4  # an empty buffer: the next draw starts a block
            bitgen.state = state
            drawn[row : row + length] = bitgen.random_raw(length * words).reshape(length, words)
            row += length
        if not direct:
            raw[valid] = drawn[rows]
        yield raw


def _counter_words(counter: int) -> NDArray[np.uint64]:
    """The four 64-bit words of a 256-bit Philox counter, lowest first."""
    mask = (1 << 64) - 1
    return np.array([(counter >> (64 * i)) & mask for i in range(4)], dtype=np.uint64)


def _normals_from_words(raw: NDArray[np.uint64], out: Array, clip: float | None) -> None:
    """``out = ndtri(((raw >> 12) + 1/2) 2**-52)``, clipped to ``[-clip, clip]`` (``raw`` is
    overwritten)."""
    from scipy.special import ndtri

    np.right_shift(raw, np.uint64(12), out=raw)
    np.add(raw, 0.5, out=out, casting="unsafe")
    out *= _TWO_TO_MINUS_52
    ndtri(out, out=out)
    if clip is not None:
        np.clip(out, -clip, clip, out=out)


def truncation_level(h: float, k: float = 2.0) -> float:
    r""":math:`A_h = \sqrt{2k \max(|\ln h|, 1)}`: where :func:`brownian_increments` clips the
    normals (Milstein–Repin–Tretyakov; the floor keeps a level of at least :math:`\sqrt{2k}`
    for steps above ``1/e``).

    Parameters
    ----------
    h : float
        The step size (positive).
    k : float
        The truncation parameter (default 2).

    Returns
    -------
    float

    Raises
    ------
    ParameterError
        A non-positive or non-finite ``h``, or ``k`` below 1.
    """
    h = _step(h)
    return math.sqrt(2.0 * _truncation(k) * max(abs(math.log(h)), 1.0))


def _step(h: Any) -> float:
    """``h`` as a float, if it is a positive finite number (not a bool)."""
    if isinstance(h, bool) or not isinstance(h, (int, float, np.integer, np.floating)):
        raise ParameterError(f"the step h must be positive and finite, got {h!r}")
    if not (math.isfinite(h) and h > 0):
        raise ParameterError(f"the step h must be positive and finite, got {h!r}")
    return float(h)


def brownian_increments(
    seed: int, members: ArrayLike, k0: int, nsteps: int, count: int, h: float, *,
    stream: int = TRANSPORT_STREAM, truncation: float | None = 2.0,
) -> Array:  # fmt: skip
    r"""Increments :math:`\Delta\beta = \sqrt h\,\zeta` of ``count`` Brownian motions over the
    steps ``k0 + 1 .. k0 + nsteps`` of size ``h``, ``(nsteps, len(members), count)``.

    ``truncation = k`` clips ``zeta`` to :math:`\pm A_h` (:func:`truncation_level`); ``None``
    draws untruncated normals.

    Parameters
    ----------
    seed : int
        The noise seed (an integer ``>= 0``).
    members : array_like of int
        The members' ids (keys of their paths); ids ``< 0`` (padding) get zeros.
    k0 : int
        Steps before the first one drawn (``>= 0``).
    nsteps : int
        Number of steps (``>= 0``).
    count : int
        Brownian motions per member (``>= 0``).
    h : float
        The step size (positive, finite).
    stream : int
        The Philox stream (an integer ``>= 0``; default ``TRANSPORT_STREAM = 0``, the
        transport noise; forcings use :data:`isoflow.splitting.FORCING_STREAM`).
    truncation : float or None
        ``k`` of :func:`truncation_level` (default 2), or ``None`` for no clipping.

    Returns
    -------
    ndarray, shape (nsteps, len(members), count)

    Raises
    ------
    ParameterError
        A non-positive or non-finite ``h``, a bad ``truncation``, or what
        :func:`standard_normals` refuses.
    """
    h = _step(h)
    clip = None
    if truncation is not None:
        clip = truncation_level(h, _truncation(truncation))
    z = standard_normals(seed, members, k0, nsteps, count, stream=stream, clip=clip)
    z *= math.sqrt(h)
    return z


def _truncation(k: Any) -> float:
    if isinstance(k, bool) or not isinstance(k, (int, float, np.integer, np.floating)):
        raise ParameterError(f"truncation must be a number k >= 1 or None, got {k!r}")
    if not (math.isfinite(k) and k >= 1):
        raise ParameterError(f"truncation must be a number k >= 1 or None, got {k!r}")
    return float(k)


def check_truncation(k: Any) -> float | None:
    """``None`` or a valid truncation exponent ``k >= 1``."""
    return None if k is None else _truncation(k)


def _in_normalizer(F: Array, algebra: Algebra, what: str) -> Array:
    """The fields ``F`` (``(m, *normalizer.shape)``) in the normalizer's dtype, if each is in
    the normalizer of ``algebra`` (``what`` names field ``i`` in the message).

    Raises
    ------
    InvalidBError
        Complex fields on a real space, or a field away from the normalizer.
    """
    norm = algebra.normalizer
    if F.dtype.kind == "c" and not norm.is_complex:
        raise InvalidBError(
            f"TransportNoise: complex fields cannot act on the real space {algebra.name}"
        )
    Fc = F.astype(norm.dtype)
    dist = np.atleast_1d(norm.distance(Fc))
    scale = np.atleast_1d(norm.norm(Fc))
    bad = np.flatnonzero(dist > 1e-12 + 1e-10 * scale)
    if bad.size:
        raise InvalidBError(
            f"TransportNoise: {what.format(int(bad[0]))} is not in the normalizer {norm.name} "
            f"of {algebra.name} (distance {float(dist[bad[0]]):.2e}): the flow would leave "
            "the space"
        )
    return Fc


@dataclass(frozen=True, eq=False)
class TransportNoise:
    r"""Stratonovich transport noise :math:`\sum_i [B_i(W), W] \circ d\beta_i` of a problem.

    Parameters
    ----------
    fields : array_like or callable, optional
        Constant fields :math:`\Xi_i`, shape ``(m, *normalizer.shape)``, each in the
        normalizer of the space (runs compiled); or a function ``W -> (*batch, m,
        *normalizer.shape)`` of state-dependent fields (give ``count = m``; NumPy path only).
    seed : int
        Seed of the increments (required): member ``j`` of a run draws from the key
        ``(seed, members[j])``.
    site : float or array_like, optional
        On particle spaces :math:`(\mathbb{R}^3, \times)^N`: isotropic site noise of amplitude
        :math:`\sigma_p` (a number, or one per particle): three independent Brownian motions
        per particle, field :math:`\sigma_p e_a` on particle ``p`` (after the ``m`` fields).
    count : int, optional
        ``m`` for a callable ``fields``.
    members : array_like of int, optional
        The run's members' ids (the keys of their increments): by default ``0 .. M - 1``; a
        sweep gives each task's members their ids in the sweep, so that the task's ensemble
        draws what one ensemble of the whole sweep draws.
    """

    fields: Any = None
    seed: int | None = None
    site: Any = None
    count: int | None = None
    members: Any = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "seed", check_seed(self.seed, "TransportNoise: seed"))
        if self.fields is not None and not callable(self.fields):
            F = np.array(self.fields, copy=True)
            if F.dtype.kind not in "iufc":
                raise ParameterError(f"TransportNoise: fields must be numbers, got {F.dtype}")
            if F.dtype.kind in "iu":
                F = F.astype(np.float64)
            if not np.all(np.isfinite(F)):
                raise ParameterError("TransportNoise: fields have non-finite entries")
            F.setflags(write=False)
            object.__setattr__(self, "fields", F)
            if self.count is not None and self.count != F.shape[0]:
                raise ShapeError(
                    f"TransportNoise: count = {self.count}, but fields holds {F.shape[0]}"
                )
            object.__setattr__(self, "count", int(F.shape[0]) if F.ndim else 0)
        elif callable(self.fields):
            c = self.count
            if isinstance(c, bool) or not isinstance(c, (int, np.integer)) or c < 1:
                raise ParameterError(
                    f"TransportNoise: a callable fields needs count = m >= 1, got {c!r}"
                )
            object.__setattr__(self, "count", int(c))
        else:
            object.__setattr__(self, "count", 0)
        if self.site is not None:
            s = np.array(self.site, dtype=np.float64, copy=True)
            if s.ndim > 1 or not np.all(np.isfinite(s)) or np.any(s < 0):
                raise ParameterError(
                    "TransportNoise: site must be a number >= 0 or one per particle, "
                    f"got {self.site!r}"
                )
            s.setflags(write=False)
            object.__setattr__(self, "site", s)
        if self.members is not None:
            ids = _members(self.members)
            if np.any(ids < 0):
                raise ParameterError("TransportNoise: members must be ids >= 0")
            ids.setflags(write=False)
            object.__setattr__(self, "members", ids)

    # ---- the space -------------------------------------------------------------------------
    def check(self, algebra: Algebra) -> None:
        """Raise if the noise does not act on ``algebra``: fields of the wrong shape or outside
        the normalizer, site noise on a space that is not :math:`(\\mathbb{R}^3, \\times)^N`.

        Raises
        ------
        ShapeError, InvalidBError, ParameterError
        """
        norm = algebra.normalizer
        F = self.fields
        if isinstance(F, np.ndarray):
            if F.ndim != 1 + len(norm.shape) or F.shape[1:] != norm.shape:
                raise ShapeError(
                    f"TransportNoise: fields must have shape (m, {', '.join(map(str, norm.shape))})"
                    f" for {algebra.name}, got {F.shape}"
                )
            Fc = _in_normalizer(F, algebra, "field {}")
            object.__setattr__(self, "fields", np.ascontiguousarray(Fc))
            self.fields.setflags(write=False)
        if self.site is not None:
            from .algebras import SpinVectors

            if not isinstance(algebra, SpinVectors):
                raise InvalidBError(
                    f"TransportNoise: site noise acts on (R^3, x)^N, not on {algebra.name}"
                )
            N = algebra.shape[0]
            if self.site.ndim == 1 and self.site.shape != (N,):
                raise ShapeError(
                    f"TransportNoise: site holds {self.site.shape[0]} amplitudes for {N} particles"
                )

    def check_fields_at(self, W: Array, algebra: Algebra) -> None:
        """Raise if a callable ``fields`` does not give ``m`` fields of the normalizer per
        member at the states ``W`` (``(*batch, *shape)``), as a step would use them.

        Parameters
        ----------
        W : ndarray, shape (*batch, *shape)
            States of the problem.
        algebra : Algebra
            The problem's space (the fields must lie in its normalizer).

        Raises
        ------
        ShapeError, InvalidBError
        """
        if not callable(self.fields):
            return
        norm = algebra.normalizer
        batch = algebra.batch_shape(W)
        want = (*batch, int(self.count or 0), *norm.shape)
        try:
            F = np.asarray(self.fields(W))
        except Exception as exc:
            raise InvalidBError(
                f"TransportNoise: the fields function raised {type(exc).__name__}: {exc}"
            ) from exc
        if F.shape != want:
            raise ShapeError(
                f"TransportNoise: the fields function must return shape {want} (the batch, "
                f"count = {self.count} fields, the normalizer {norm.name}), got {F.shape}"
            )
        if not np.all(np.isfinite(F)):
            raise InvalidBError("TransportNoise: the fields function returned non-finite values")
        _in_normalizer(F.reshape(-1, *norm.shape), algebra, "field {} of the fields function")

    def particles(self, algebra: Algebra) -> int:
        """Particles with site noise (``0`` without).

        Parameters
        ----------
        algebra : Algebra
            The problem's space (its shape gives the number of particles ``N``).

        Returns
        -------
        int
        """
        return 0 if self.site is None else int(algebra.shape[0])

    def dimension(self, algebra: Algebra) -> int:
        """Brownian motions per member: ``m`` plus three per particle of site noise.

        Parameters
        ----------
        algebra : Algebra
            The problem's space (its shape gives the number of particles ``N``).

        Returns
        -------
        int
        """
        return int(self.count or 0) + 3 * self.particles(algebra)

    def site_amplitudes(self, algebra: Algebra) -> Array:
        """:math:`\\sigma_p` per particle, ``(N,)`` (empty without site noise).

        Parameters
        ----------
        algebra : Algebra
            The problem's space (its shape gives the number of particles ``N``).

        Returns
        -------
        ndarray, shape (N,) or (0,)
        """
        P = self.particles(algebra)
        if P == 0:
            return np.zeros(0)
        return np.ascontiguousarray(np.broadcast_to(self.site, (P,)), dtype=np.float64)

    def member_ids(self, members: int) -> NDArray[np.int64]:
        """The ids of a run's ``members`` members (their keys).

        Raises
        ------
        ShapeError
            ``members`` given for another number of members.
        """
        if self.members is None:
            return np.arange(members, dtype=np.int64)
        if self.members.shape != (members,):
            raise ShapeError(
                f"TransportNoise: {self.members.size} member ids for a run of {members} members"
            )
        return self.members

    def with_members(self, members: Sequence[int] | ArrayLike) -> TransportNoise:
        """The same noise for members with the ids ``members`` (e.g. a sweep's task)."""
        return TransportNoise(self.fields, self.seed, self.site, self.count, members)

    # ---- evaluation (NumPy) ----------------------------------------------------------------
    def increment(self, W: Array, dbeta: Array, algebra: Algebra) -> Array:
        r""":math:`\sum_i \Delta\beta_i B_i(W)` (site noise included), ``(*batch,
        *normalizer.shape)``, for the increments ``dbeta`` ``(*batch, dimension)``.

        Parameters
        ----------
        W : ndarray, shape (*batch, *shape)
            The states (where callable fields are evaluated).
        dbeta : ndarray, shape (*batch, dimension)
            The Brownian increments: the ``m`` fields' first, then three per particle of site
            noise.
        algebra : Algebra
            The problem's space.

        Returns
        -------
        ndarray, shape (*batch, *normalizer.shape)
        """
        norm = algebra.normalizer
        batch = algebra.batch_shape(W)
        m = int(self.count or 0)
        db = np.asarray(dbeta, dtype=np.float64).reshape(*batch, -1)
        out = np.zeros((*batch, *norm.shape), dtype=norm.dtype)
        if m:
            F = self.fields(W) if callable(self.fields) else self.fields
            F = np.asarray(F)
            axes = "abcdefgh"[: len(norm.shape)]
            if callable(self.fields):
                out = out + np.einsum(f"...i,...i{axes}->...{axes}", db[..., :m], F)
            else:
                out = out + np.einsum(f"...i,i{axes}->...{axes}", db[..., :m], F)
        P = self.particles(algebra)
        if P:
            amp = self.site_amplitudes(algebra)
            out = out + amp[:, None] * db[..., m:].reshape(*batch, P, 3)
        return out

    def parameters(self) -> dict[str, Any]:
        """What a problem records about its noise (``problem.parameters["noise"]``)."""
        out: dict[str, Any] = {"seed": self.seed, "count": self.count}
        if isinstance(self.fields, np.ndarray):
            out["fields"] = self.fields
        if self.site is not None:
            out["site"] = self.site
        return out
