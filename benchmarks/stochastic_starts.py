r"""Iterations of the stochastic IsoMP's stage solve from better starts (benchmark 18's ensemble).

Benchmark 18's so(10) rigid body with one noise field (norm 0.3, ``h = 0.1``, state of norm
0.1) takes about 9 fixed-point iterations a step against IsoMP's 3 with its extrapolated start.
This script asks whether a better start would close the gap: the same path (one member, 200
steps, seed 0, tolerance at the rounding floor as the compiled loop's default), each step's
stage solved from

* ``state``: ``X = W`` (what the stochastic IsoMP does);
* ``noise 1``, ``noise 2``: the exact stage of the noise alone, :math:`X = (I - A/2)^{-1} W
  (I + A/2)^{-1}` with :math:`A = \Delta\beta\,\Xi`, to first and second order in ``A``;
* ``noise 2 + field``: the same with :math:`A = h B(W) + \Delta\beta\,\Xi` (one more
  evaluation of ``B``);
* ``noise 2 + last miss``: ``noise 2`` plus what it missed on the previous step (the
  deterministic part, extrapolated at order zero);

and the Cayley-preconditioned iteration :math:`X \leftarrow C W C^T`, :math:`C = (I - A(X)/2)^{-1}`
(the linear part solved exactly each iteration). Run: ``python benchmarks/stochastic_starts.py``.

Measured (2026-11-26): 10.1 iterations from the state, 9.3 and 9.2 from the noise's stage to
first and second order, 8.5 with the field, 8.4 with the last step's miss; the preconditioned
iteration 8.3. Each iteration gains about one digit (the contraction, about ``|A| / 2``, is set
by the step's increment), so a start better by ``10^k`` saves about ``k`` iterations; the
increments are fresh every step, so no start here comes close to the smooth extrapolation
that gets IsoMP to about 3: these starts save at most two of the ten.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def main(steps: int = 200) -> dict[str, float]:
    """Mean iterations per step for each start (see the module docstring)."""
    import isoflow as iso

    alg = iso.algebras.so(10)
    field = alg.random(seed=5)
    Xi = 0.3 * field / np.linalg.norm(field)
    problem, _ = iso.models.rigid_body(10)
    B = problem.B
    h = 0.1
    eye = np.eye(10)

    def bracket(a: Any, b: Any) -> Any:
        return a @ b - b @ a

    def solve(X: Any, W: Any, A0: Any, tol: float, cayley: bool = False) -> tuple[int, Any]:
        for k in range(1, 100):
            A = h * B(X) + A0
            if cayley:
                C = np.linalg.inv(eye - 0.5 * A)
                Xn = C @ W @ C.T
            else:
                Xn = W + 0.5 * bracket(A, X) + 0.25 * A @ X @ A
            if np.linalg.norm(Xn - X) <= tol:
                return k, Xn
            X = Xn
        raise RuntimeError("no convergence")

    def second_order(A: Any, W: Any) -> Any:
        return W + 0.5 * bracket(A, W) + 0.25 * (A @ A @ W + W @ A @ A - A @ W @ A)

    rng = np.random.default_rng(0)
    W = alg.random(seed=0, scale=0.1)
    totals = dict.fromkeys(
        ("state", "noise 1", "noise 2", "noise 2 + field", "noise 2 + last miss", "cayley"), 0
    )
    miss = None
    for _ in range(steps):
        A0 = rng.normal() * np.sqrt(h) * Xi
        tol = 2e-16 * (1.0 + np.linalg.norm(W))
        k, X = solve(W.copy(), W, A0, tol)
        totals["state"] += k
        totals["noise 1"] += solve(W + 0.5 * bracket(A0, W), W, A0, tol)[0]
        P2 = second_order(A0, W)
        totals["noise 2"] += solve(P2, W, A0, tol)[0]
        totals["noise 2 + field"] += solve(second_order(h * B(W) + A0, W), W, A0, tol)[0]
        totals["noise 2 + last miss"] += solve(P2 + (0 if miss is None else miss), W, A0, tol)[0]
        totals["cayley"] += solve(W.copy(), W, A0, tol, cayley=True)[0]
        miss = X - P2
        A = h * B(X) + A0
        W = W + bracket(A, X)
        W = 0.5 * (W - W.T)
    return {name: total / steps for name, total in totals.items()}


if __name__ == "__main__":
    for name, mean in main().items():
        print(f"{name:22s} {mean:5.2f} iterations a step")
