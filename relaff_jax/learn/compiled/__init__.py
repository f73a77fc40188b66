"""The compiled forest engine (numba)."""
from relaff_jax.learn.compiled.forest import Forest, fit, fit_many, kernels

__all__ = ["Forest", "fit", "fit_many", "kernels"]
