"""A user's own models, as a user writes them for ``isoflow run --model user_models:...``.

Importable from a subprocess with ``PYTHONPATH`` set to this directory (the tests do that).
"""

from __future__ import annotations

import numpy as np

import isoflow as iso
from isoflow.registry import ModelSpec, Param


def toy_rigid_body(n: int = 4, scale: float = 0.5, seed: int = 0):
    """A rigid body on so(n) with a plain Python ``B`` (the NumPy path)."""
    d = 1.0 + np.arange(n) / n
    C = 0.5 * (d[:, None] + d[None, :])

    def B(W):
        return -C * W

    def H(W):
        return 0.5 * np.sum(C * W * W, axis=(-2, -1))

    alg = iso.algebras.so(n)
    problem = iso.IsospectralProblem(B=B, algebra=alg, hamiltonian=H, name="toy rigid body")
    return problem, alg.random(seed=seed, scale=scale)


def compiled_toy(n: int = 4, seed: int = 0):
    """The cubic elementwise field of ``user_kernels`` as a compiled ``B`` (``iso.CompiledB``)."""
    import user_kernels

    d = 1.0 + np.arange(n) / n
    C = 0.5 * (d[:, None] + d[None, :])
    alg = iso.algebras.so(n)
    problem = iso.IsospectralProblem(
        algebra=alg, kernel=iso.CompiledB(user_kernels.cubic_elementwise, (C,))
    )
    return problem, alg.random(seed=seed, scale=0.3)


def raising_toy(scale: float = 0.1, limit: float = 1.4):
    """A compiled ``B`` on so(4) that raises once an entry of ``W`` exceeds ``limit``
    (``user_kernels.raises_when_large``): a member of scale 0.8 raises in the middle of a run
    of 40 steps of 0.05, members of scale 0.1 and 0.2 never do."""
    import user_kernels

    C = 0.5 * np.add.outer(np.arange(1.0, 5.0), np.arange(1.0, 5.0))
    alg = iso.algebras.so(4)
    kernel = iso.CompiledB(user_kernels.raises_when_large, (C, float(limit)))
    return iso.IsospectralProblem(algebra=alg, kernel=kernel), alg.random(23, scale=scale)


def not_a_model(n: int = 3):
    """Returns the wrong thing."""
    return np.zeros((n, n))


#: The same toy model with declared parameters (what a package points its entry point at).
TOY_SPEC = ModelSpec(
    "toy",
    toy_rigid_body,
    {
        "n": Param(int, 4, "matrix size", low=2, high=64),
        "scale": Param(float, 0.5, "norm of W0", low=0.0),
        "seed": Param(int, 0, "seed", low=0),
    },
    "a toy rigid body",
)


def scaled_rigid_body(c: float = 1.0, seed: int = 0):
    """The rigid body of :func:`toy_rigid_body` with its field scaled by ``c`` (a parameter
    that changes ``B``, not the state's shape)."""
    problem, W0 = toy_rigid_body(seed=seed)
    B = problem.B
    return iso.IsospectralProblem(B=lambda W: c * B(W), algebra=problem.algebra), W0
