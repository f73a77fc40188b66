"""Real point clouds (paper section VI): reading, the paper's segmentation, table frame, features.

Stages, in order (each file's docstring gives its inputs and outputs):

- ``cloud.py``: ``RealCloud`` (xyz (H, W, 3) camera metres, NaN invalid; rgb; label; other
  fields; intrinsics), ``make_cloud``, ``estimate_intrinsics``, segment-map codes;
- ``lzf.py``: LZF (de)compression for PCD binary_compressed;
- ``pcd.py`` / ``ply.py`` / ``readers.py``: ``read_pcd``, ``read_ply``, ``read_npz``,
  ``read_cloud`` (by extension) and their writers;
- the settings (``RealRunConfig``, ``RealConfig``, ``pipeline_config``) are ``relaff_jax.config.real``
  (its pipeline settings with the tree's shared perception);
- ``ransac.py``: RANSAC plane and k-means in JAX (pure, keyed; the caller jits);
- ``segment.py``: ``segment_scene`` (table plane, crop, k-means), ``hand_segmentation``;
- ``frame.py``: ``table_frame``, ``camera_pose``, ``camera_pose_stats``, ``sim_camera``;
- ``cloud_features.py``: ``cloud_normals``, ``pair_features``, ``object_pair_features``;
- ``score.py``: IoU of a segmentation against the hand one, over scenes;
- ``survey.py``: camera pose (height, tilt) over a folder of scenes, reader speed;
- ``show.py``: ``render_real_scene_png`` (colour, segmentations, voxel clouds, PCA frames);

Relations and section VI's experiments (on top of the above):

- ``labels.py``: the labels file (scene, object a, object b, relation, sha256): read, validate, write;
- ``propose.py`` / ``pictures.py`` / ``labelling.py``: the geometric rule proposing a relation per
  pair, one picture per pair to check it by eye, a folder to proposals;
- ``scene_source.py`` / ``real_data.py``: a labelled folder to pair features, camera poses, the
  matching simulated sensor;
- ``sim_relations.py``: settled simulated scenes seen from the real sensor's pose (cached, resumable);
- ``experiments.py``: SIM -> SIM, REAL -> REAL, SIM -> REAL and REAL <- SIM (paper Figs. 14-15);
- ``report.py`` / ``study.py``: figures, claims a-d, one resumable output folder;
- ``folder.py``: that output folder's layout, each file named once;
- ``stages.py``: one entry point per ``relaff real`` command over the whole config tree
  (``run_segment``, ``run_show``, ``run_propose``, ``run_check``; ``run_study`` from ``study.py``).
"""
from __future__ import annotations

from relaff_jax.lazy import lazy_attributes

# Names are loaded on first use (PEP 562), so that the labels
# file can be read without importing JAX (a ``--set`` mistake is reported at once).
_WHERE = {
    "FIRST_OBJECT": "cloud",
    "SEG_NONE": "cloud",
    "SEG_TABLE": "cloud",
    "RealCloud": "cloud",
    "estimate_intrinsics": "cloud",
    "make_cloud": "cloud",
    "cloud_normals": "cloud_features",
    "object_pair_features": "cloud_features",
    "object_points": "cloud_features",
    "pair_features": "cloud_features",
    "camera_pose": "frame",
    "camera_pose_stats": "frame",
    "sim_camera": "frame",
    "table_frame": "frame",
    "to_table": "frame",
    "vectors_to_table": "frame",
    "read_pcd": "pcd",
    "write_pcd": "pcd",
    "read_ply": "ply",
    "write_ply": "ply",
    "FORMATS": "readers",
    "read_cloud": "readers",
    "read_npz": "readers",
    "write_npz": "readers",
    "object_ious": "score",
    "score_scene": "score",
    "score_scenes": "score",
    "fit_table_plane": "segment",
    "hand_segmentation": "segment",
    "object_ids": "segment",
    "segment_scene": "segment",
    "real_scene_view": "show",
    "render_real_scene_png": "show",
    "camera_poses": "survey",
    "read_speed": "survey",
    "run_sim_only": "experiments",
    "run_space": "experiments",
    "summarise": "experiments",
    "Label": "labels",
    "read_labels": "labels",
    "relation_counts": "labels",
    "validate": "labels",
    "write_labels": "labels",
    "propose_scene": "propose",
    "build_sim_relations": "sim_relations",
    "load_sim_relations": "sim_relations",
    "run_study": "study",
    "run_segment": "stages",
    "run_show": "stages",
    "run_propose": "stages",
    "run_check": "stages",
    "read_corrections": "stages",
}


__getattr__, __dir__ = lazy_attributes(__name__, _WHERE, globals())


__all__ = sorted(_WHERE)
