"""MJCF files of the relaff_jax world (table, arm); shipped as ``relaff_jax.scenes``."""
