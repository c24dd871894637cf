r"""Compiled time loops (numba): one driver, a stage per state layout, kernels plugged in.

This layer depends on the numerical core (problems, methods, solvers, kernels) and never the
other way round: the methods do not import it; the time loop (:mod:`isoflow._solve`) asks
:func:`compiled_runner` for a compiled runner and otherwise runs the method's own steps.

Modules
-------
``runner``
    Which layout and stage a run gets (:func:`compiled_runner`) and the chunked runs.
``driver``
    The one time loop over members and steps: initial guess, stopping rules, Anderson mixing,
    failure bookkeeping, the ring of stage offsets, saving into output rows.
``flat``
    The layout-free pieces on flat vectors (guess, ring, Anderson, reductions).
``dense``, ``particles``, ``spin_chain``
    The stages: one fixed-point iteration and the new state, per layout.
``rules``
    The stopping rules of :mod:`isoflow.nonlinear`, compiled.

Compilations are timed and announced by :mod:`isoflow._compile_clock` (outside this package,
so that the time loop can start the clock without importing the compiled layer).
"""

from .runner import CompiledRunner, compiled_runner

__all__ = ["CompiledRunner", "compiled_runner"]
