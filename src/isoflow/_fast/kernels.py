"""Transitional re-export: the kernels now live in :mod:`isoflow.kernels`."""

from ..kernels import ElementwiseLinear, Kernel, PairwiseVortex, SpinNeighbourSum

FastKernel = Kernel

__all__ = ["ElementwiseLinear", "FastKernel", "PairwiseVortex", "SpinNeighbourSum"]
