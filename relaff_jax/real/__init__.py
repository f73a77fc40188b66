"""Real point clouds (paper section VI): reading, the paper's segmentation, table frame, features.

Stages, in order (each file's docstring gives its inputs and outputs):

- ``cloud.py``: ``RealCloud`` (xyz (H, W, 3) camera metres, NaN invalid; rgb; label; other
  fields; intrinsics), ``make_cloud``, ``estimate_intrinsics``, segment-map codes;
- ``lzf.py``: LZF (de)compression for PCD binary_compressed;
- ``pcd.py`` / ``ply.py`` / ``readers.py``: ``read_pcd``, ``read_ply``, ``read_npz``,
  ``read_cloud`` (by extension) and their writers;
- ``config.py``: ``RealConfig`` (plane, crop, k-means, normals, shared perception settings);
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
- ``report.py`` / ``study.py``: figures, claims a-d, one resumable output folder.
"""
from __future__ import annotations

from .cloud import FIRST_OBJECT, SEG_NONE, SEG_TABLE, RealCloud, estimate_intrinsics, make_cloud
from .cloud_features import cloud_normals, object_pair_features, object_points, pair_features
from .config import CropConfig, KMeansConfig, NormalConfig, PlaneConfig, RealConfig, validate_real_config
from .frame import camera_pose, camera_pose_stats, sim_camera, table_frame, to_table, vectors_to_table
from .pcd import read_pcd, write_pcd
from .ply import read_ply, write_ply
from .readers import FORMATS, read_cloud, read_npz, write_npz
from .score import object_ious, score_scene, score_scenes
from .segment import fit_table_plane, hand_segmentation, object_ids, segment_scene
from .show import real_scene_view, render_real_scene_png
from .survey import camera_poses, read_speed
from .experiments import RealExperimentConfig, run_sim_only, run_space, summarise
from .labels import Label, read_labels, relation_counts, validate, write_labels
from .propose import RuleConfig, propose_scene
from .sim_relations import SimRelationConfig, SimSensor, build_sim_relations, load_sim_relations
from .study import run_study
