"""Compiled (numba) fast paths of the time loops; see :mod:`isoflow._fast.kernels`."""

from .kernels import ElementwiseLinear, FastKernel, SpinNeighbourSum

__all__ = ["ElementwiseLinear", "FastKernel", "SpinNeighbourSum"]
