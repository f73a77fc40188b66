"""Perception: the simulated Kinect (ray casting, depth noise), voxel grids, PCA and RHF
descriptors, and the glue from stored scenes to features."""
