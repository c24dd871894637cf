r"""The fingerprint of a model: what a result file records so that a resume notices a change.

A run streamed to a file continues, on resume, with the problem rebuilt from the file's
configuration or handed over by the caller. If the model's code changed in between (a user's
factory module edited, a factor 2 in ``B``), the file would silently mix two flows. So a run
records, when it starts, a fingerprint of its model (:func:`model_fingerprint`), and a resume
recomputes it and names what differs (:func:`fingerprint_changes`):

* **the model's functions at a probe state**: ``B``, the noise term of a problem with transport
  noise (its fields at the first member's first increments: the seed and the member ids
  count) and the functions behind the file's
  diagnostics (the Hamiltonian, the Lyapunov function, the invariants) evaluated at the run's
  first initial state plus a fixed perturbation of relative size :data:`PROBE_SIZE` (generic:
  it breaks the symmetries of special initial states), each summarized by its norm and
  :data:`DIRECTIONS` fixed projections. They are compared to a relative :data:`RTOL`: rounding
  differences between machines, BLAS builds and thread counts pass, any change of the model
  does not. The perturbation and the projections are Weyl sequences ``frac(k alpha)`` (the same
  bits everywhere, no random stream whose version could change);
* **the source** of the code defining ``B`` and a :class:`~isoflow.CompiledB` function, when it
  is not isoflow's own: the SHA-256 of the module's file (a user factory module), or of the
  function's own source for a script or notebook (``__main__``), whose resume often runs from
  another script.

Model parameters are not compared on their own: those that change the flow change ``B`` at the
probe, the others only set the initial data, which a resume does not use.
"""

from __future__ import annotations

import functools
import hashlib
import inspect
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .kernels import CompiledB
from .problems import IsospectralProblem

__all__ = [
    "DIRECTIONS",
    "FINGERPRINT_VERSION",
    "PROBE_SIZE",
    "RTOL",
    "fingerprint_changes",
    "model_fingerprint",
]

Array = NDArray[Any]

#: Version of the fingerprint's layout (a file recording another version is not compared).
FINGERPRINT_VERSION = 1
#: Relative size of the perturbation of the initial state that makes the probe state.
PROBE_SIZE = 1e-3
#: Relative tolerance of the comparison of the values at the probe state.
RTOL = 1e-9
#: Fixed projections of every value recorded besides its norm.
DIRECTIONS = 3
#: Irrational multipliers of the Weyl sequences: the perturbation (real, imaginary part), then
#: the projections.
_ALPHAS = (
    (math.sqrt(5.0) - 1.0) / 2.0,
    math.sqrt(2.0) - 1.0,
    math.sqrt(3.0) - 1.0,
    math.sqrt(7.0) - 2.0,
    math.sqrt(11.0) - 3.0,
)


def _weyl(n: int, alpha: float) -> Array:
    """``2 frac(k alpha) - 1`` for ``k = 1..n``: in ``[-1, 1)``, equidistributed, and the
    same bits on every machine (one rounded product and exact operations)."""
    x = np.arange(1, n + 1, dtype=np.float64) * alpha
    return 2.0 * (x - np.floor(x)) - 1.0


def _first_member(problem: IsospectralProblem, W: Array) -> Array:
    """The first member of ``W``, keeping one leading axis when ``W`` is an ensemble."""
    alg = problem.algebra
    return np.asarray(W).reshape(-1, *alg.shape)[:1] if alg.batch_shape(W) else np.asarray(W)


def _probe_state(problem: IsospectralProblem, first: Array) -> Array:
    """``first`` plus a fixed perturbation in the space of relative size :data:`PROBE_SIZE`."""
    alg = problem.algebra
    size = int(np.prod(alg.shape))
    d = _weyl(size, _ALPHAS[0])
    if alg.is_complex:
        d = d + 1j * _weyl(size, _ALPHAS[1])
    R = np.asarray(alg.project(d.reshape(alg.shape).astype(alg.dtype)))
    scale = float(np.linalg.norm(first)) or 1.0
    return first + (PROBE_SIZE * scale / float(np.linalg.norm(R))) * R


def _sketch(value: Any) -> list[float] | None:
    """``[norm, <v, d_1>, ..., <v, d_k>]`` of the array ``value`` flattened to real numbers
    (unit Weyl directions ``d_j``), or ``None`` if it is not a finite numeric array."""
    v = np.asarray(value)
    if v.dtype.kind not in "biufc":
        return None
    flat = v.reshape(-1)
    real = np.concatenate([flat.real, flat.imag]) if v.dtype.kind == "c" else flat
    real = real.astype(np.float64)
    if not np.all(np.isfinite(real)):
        return None
    out = [float(np.linalg.norm(real))]
    for alpha in _ALPHAS[2 : 2 + DIRECTIONS]:
        d = _weyl(real.size, alpha)
        out.append(float(real @ d) / (float(np.linalg.norm(d)) or 1.0))
    return out


def _values_at(problem: IsospectralProblem, P: Array) -> dict[str, list[float] | None]:
    """The sketches of ``B`` and the diagnostics' functions at ``P`` (``None`` where one
    raises or is not finite)."""
    functions: dict[str, Callable[[Array], Any]] = {"B": problem.evaluate_B}
    if problem.hamiltonian is not None:
        functions["hamiltonian"] = problem.hamiltonian
    if problem.lyapunov is not None:
        functions["lyapunov"] = problem.lyapunov
    for name, fn in problem.invariants.items():
        functions[f"invariant {name}"] = fn
    for name, fn in problem.observables.items():
        functions[f"observable {name}"] = fn
    if problem.noise is not None:
        functions["noise"] = functools.partial(_noise_probe, problem)
    out: dict[str, list[float] | None] = {}
    for name, fn in functions.items():
        try:
            out[name] = _sketch(fn(P))
        except Exception:  # a function undefined at the probe: recorded as such
            out[name] = None
    return out


def _noise_probe(problem: IsospectralProblem, P: Array) -> Array:
    """The noise term of the first member's first step at ``P``: its fields, amplitudes, seed
    and member id in one value (:class:`~isoflow.noise.TransportNoise`)."""
    from .noise import standard_normals

    noise = problem.noise
    assert noise is not None
    first = 0 if noise.members is None else int(noise.members[0])
    z = standard_normals(noise.seed, [first], 0, 1, noise.dimension(problem.algebra))[0, 0]  # type: ignore[arg-type]
    return noise.increment(P, z, problem.algebra)


def _plain_function(f: Any) -> Any:
    """The Python function behind ``f`` (a partial, a numba dispatcher, a bound method, a
    callable object), or ``None``."""
    for _ in range(8):
        if isinstance(f, functools.partial):
            f = f.func
        elif hasattr(f, "py_func"):
            f = f.py_func
        elif inspect.ismethod(f):
            f = f.__func__
        elif inspect.isfunction(f):
            return f
        elif callable(f):
            f = type(f).__call__
        else:
            return None
    return None


def _source_hash(f: Any) -> tuple[str, str] | None:
    """``(what, sha256)`` of the code defining ``f``, ``None`` for isoflow's own code and
    where no source is available."""
    fn = _plain_function(f)
    if fn is None:
        return None
    name = str(getattr(fn, "__module__", "") or "")
    if name == "isoflow" or name.startswith("isoflow."):
        return None
    path = getattr(getattr(fn, "__code__", None), "co_filename", None)  # its module's file
    if name != "__main__" and path:
        try:
            with open(path, "rb") as fh:
                return f"module {name}", hashlib.sha256(fh.read()).hexdigest()
        except OSError:
            pass
    try:
        text = inspect.getsource(fn)
    except (OSError, TypeError):
        return None
    return f"function {name}.{fn.__qualname__}", hashlib.sha256(text.encode()).hexdigest()


def _sources(problem: IsospectralProblem) -> dict[str, str]:
    functions: list[Any] = [problem.B]
    if isinstance(problem.kernel, CompiledB):
        functions.append(problem.kernel.f)
    out: dict[str, str] = {}
    for f in functions:
        found = _source_hash(f)
        if found is not None:
            out[found[0]] = found[1]
    return out


def model_fingerprint(problem: IsospectralProblem, W: Array) -> dict[str, Any]:
    """The fingerprint of ``problem`` for a run from ``W`` (JSON-ready; see the module
    docstring). Costs one evaluation of ``B`` (and of the diagnostics' functions) on one
    member; never raises for a function that fails at the probe state."""
    first = _first_member(problem, W)
    at = "perturbed"
    values = _values_at(problem, _probe_state(problem, first))
    if values["B"] is None:  # B undefined near the initial state: probe the state itself
        at = "initial"
        values = _values_at(problem, first)
    return {
        "version": FINGERPRINT_VERSION,
        "probe": at,
        "values": values,
        "sources": _sources(problem),
    }


def _value_change(name: str, then: Any, now: Any) -> str | None:
    """What changed between two sketches of the function ``name``, or ``None``."""
    if then is None and now is None:
        return None
    if then is None or now is None:
        state = "is now undefined" if now is None else "is now defined"
        return f"{name} {state} at the probe state"
    try:
        a, b = np.asarray(then, dtype=float), np.asarray(now, dtype=float)
    except (TypeError, ValueError):
        return f"the file's record of {name} is malformed"
    if a.shape != b.shape or a.ndim != 1 or a.size < 1:
        return f"{name} changed at the probe state"
    scale = max(abs(float(a[0])), abs(float(b[0])))
    gap = float(np.max(np.abs(a - b)))
    if gap <= RTOL * scale:
        return None
    return f"{name} differs at the probe state by {gap / scale:.1e} (relative)"


def _dict(x: Any) -> dict[str, Any]:
    return x if isinstance(x, dict) else {}


def _values_changes(then: dict[str, Any], now: dict[str, Any]) -> list[str]:
    """What differs between two records of the functions' values at the probe state."""
    changes: list[str] = []
    for name in sorted(set(then) | set(now)):
        if name not in now:
            changes.append(f"the model no longer has its {name}")
        elif name not in then:
            changes.append(f"the model has a new {name}")
        else:
            change = _value_change(name, then[name], now[name])
            if change:
                changes.append(change)
    return changes


def fingerprint_changes(recorded: Any, current: dict[str, Any]) -> list[str]:
    """What differs between the fingerprint a file ``recorded`` and the ``current`` one, in
    words (empty: the same model). A recorded fingerprint of another version, or none, is
    not compared."""
    rec = _dict(recorded)
    if rec.get("version") != FINGERPRINT_VERSION:
        return []
    changes: list[str] = []
    if rec.get("probe") == current["probe"]:
        changes += _values_changes(_dict(rec.get("values")), current["values"])
    elif current["probe"] == "initial":
        changes.append("B is now undefined at the probe state")
    else:
        changes.append("B is now defined at the probe state, where it was not")
    then_src, now_src = _dict(rec.get("sources")), current["sources"]
    for what in sorted(set(then_src) | set(now_src)):
        if then_src.get(what) != now_src.get(what):
            changes.append(f"the source of {what} changed")
    return changes
