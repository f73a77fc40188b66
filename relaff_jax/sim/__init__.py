"""Simulation: the object library, one MJX world for every pair, scene sampling and settling,
the 6-DOF arm, the nine motor programs and their physics labels, and MuJoCo C references."""
