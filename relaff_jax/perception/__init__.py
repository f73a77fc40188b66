"""Perception (paper section IV-B): simulated Kinect -> segmented clouds -> PCA and RHF features.

Takes one settled scene described by its geoms (``SceneGeoms``: static MuJoCo geom types and
segment labels, per-scene sizes, positions and rotation matrices in the robot frame) and a
PRNG key; returns the paper's two state spaces for that scene:

* ``pca``  (18,)  toy's 9 values then the other object's 9 (centroid xyz, roll/pitch/yaw of
  the eigenvector frame, three eigenvalues), canonical order, the learning stage reorders;
* ``rhf``  (300,) six 50-bin relational histograms over all (toy point, other point) pairs;
* ``unseen`` (2,) flags, ``n_points`` (2,) voxel counts and overflow flags.

Stages, each a pure single-scene function (vmap at the caller, the caller owns jit):

1. ``render``      : pinhole depth camera, one ray per pixel cast against the geoms with our
                     own ray-primitive intersection (plane, sphere, capsule, box); the hit
                     geom's segment label stands in for colour segmentation. The feature path
                     uses ``render_objects`` (the same rays, only in image tiles that can show
                     an object) and ``compact_objects`` (object pixels into a fixed buffer).
2. ``add_depth_noise``: z noise in the camera frame (RobWork model, or Khoshelham-Elberink,
                     Nguyen), keyed.
3. ``voxel_downsample``: per object, one point per occupied 0.0125 m voxel at the centroid of
                     its points (Open3D ``voxel_down_sample`` semantics), fixed capacity, overflow
                     flagged.
4. ``pca_object``  : centroid, roll/pitch/yaw, eigenvalues; ``unseen`` below ``min_points``.
5. ``rhf_histograms``: normals averaged per voxel; six histograms, computed tile by tile so
                     memory does not grow with the point count. Normals (``cfg.normals.source``):
                     "ray" the exact ray-hit geometry (default), "cloud" PCA over a 5 x 5 pixel
                     window of the noisy points (``window_normals``, the rule real clouds can use).

``features`` chains them for one scene; ``make_batched_features`` builds the jitted batch
version once; ``render_scene_png`` draws what the robot saw. Exact definitions (camera pose,
noise formulas, voxel grid origin, angle convention, sign rule, RHF bins) are in
docs/perception.md.

Files, in dependency order (this module re-exports their public names):

- the settings and feature names: ``relaff_jax.config.perception``;
- ``ops.py``: scatter and prefix-sum primitives with fast XLA CPU batching;
- ``scene.py``: ``SceneGeoms`` (the geoms of one scene), ``make_scene``, bounding spheres;
- ``camera.py``: camera pose, intrinsics, per-pixel and per-tile rays (static numpy);
- ``raycast.py``: ray/primitive intersections and surface normals (``cast_rays``);
- ``render.py``: stage 1, depth images, tile culling, object pixel compaction;
- ``noise.py``: stage 2, depth noise models;
- ``normals.py``: normals from the cloud (image-window PCA), shared with real organized clouds;
- ``voxels.py``: stage 3, per-object voxel grid;
- ``descriptors.py``: stages 4-5, PCA values and RHF histograms;
- ``pipeline.py``: ``object_pixels`` (stage 1) and ``cloud_from_pixels`` (stages 2-3), together
  ``point_cloud``; ``features``, ``make_batched_features``;
- ``culled.py``: ``make_culled_features`` (the batched chain with capacities sized per call, same bits);
- ``plots.py``: ``scene_view`` and ``render_scene_png`` (pyplot-free);
- ``from_sim.py``: dataset samples -> features (``make_feature_fn``,
  ``show_scene``); not imported here (it needs MJX and the world);
- ``rollout_view.py``: frames of a replayed rollout (``relaff show --gif``); not imported here.

Importing this package imports JAX (every stage above is JAX code); the settings live in
``relaff_jax.config.perception`` so that the command line checks them without it.
"""

from __future__ import annotations

from relaff_jax.constants import OBJECT_SEGMENTS, SEG_BACKGROUND, SEG_NONE, SEG_OTHER, SEG_TOY
from relaff_jax.perception.camera import camera_frame, camera_rays, intrinsics, tile_rays
from relaff_jax.perception.culled import (PIXEL_BUCKETS, TILE_BUCKETS, capacity_config, make_culled_features,
                                          make_tile_counter, pixel_capacity, tile_capacity)
from relaff_jax.perception.descriptors import (fast_arccos, pca_frame, pca_object, rhf_bin, rhf_histograms,
                                               rhf_pair_values, rotation_to_rpy)
from relaff_jax.perception.noise import NOISE_MODELS, add_depth_noise, depth_noise_sigma, pixel_radius
from relaff_jax.perception.normals import pixel_normals, smallest_eigenvector, window_normals
from relaff_jax.perception.pipeline import (SceneFeatures, cloud_from_pixels, features, features_from_voxels,
                                            make_batched_features, object_pixels, point_cloud)
from relaff_jax.perception.plots import object_crop, render_scene_png, scene_view
from relaff_jax.perception.raycast import cast_rays, surface_normals
# the function ``render`` shadows its submodule's name on the package (the import binds it last)
from relaff_jax.perception.render import active_tiles, compact_objects, render, render_objects
from relaff_jax.perception.scene import (GEOM_BOX, GEOM_CAPSULE, GEOM_PLANE, GEOM_SPHERE, SUPPORTED_GEOMS,
                                         SceneGeoms, bounding_radius, make_scene, scene_from_mujoco, scene_layout)
from relaff_jax.perception.voxels import voxel_downsample

__all__ = [
    "OBJECT_SEGMENTS", "SEG_BACKGROUND", "SEG_NONE", "SEG_OTHER", "SEG_TOY",
    "camera_frame", "camera_rays", "intrinsics", "tile_rays",
    "fast_arccos", "pca_frame", "pca_object", "rhf_bin", "rhf_histograms", "rhf_pair_values",
    "rotation_to_rpy",
    "NOISE_MODELS", "add_depth_noise", "depth_noise_sigma", "pixel_radius",
    "pixel_normals", "smallest_eigenvector", "window_normals",
    "SceneFeatures", "cloud_from_pixels", "features", "features_from_voxels", "make_batched_features",
    "object_pixels", "point_cloud",
    "PIXEL_BUCKETS", "TILE_BUCKETS", "capacity_config", "make_culled_features", "make_tile_counter",
    "pixel_capacity", "tile_capacity",
    "object_crop", "render_scene_png", "scene_view",
    "cast_rays", "surface_normals",
    "active_tiles", "compact_objects", "render", "render_objects",
    "GEOM_BOX", "GEOM_CAPSULE", "GEOM_PLANE", "GEOM_SPHERE", "SUPPORTED_GEOMS", "SceneGeoms",
    "bounding_radius", "make_scene", "scene_from_mujoco", "scene_layout",
    "voxel_downsample",
]
