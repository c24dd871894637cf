"""Compiled (numba) fast paths of the time loops; see :mod:`isoflow._fast.kernels`."""

from .kernels import ElementwiseLinear, FastKernel, PairwiseVortex, SpinNeighbourSum

__all__ = ["ElementwiseLinear", "FastKernel", "PairwiseVortex", "SpinNeighbourSum"]
