"""MJCF files of the relaff_jax world (the arm); shipped as ``relaff_jax.assets``."""
