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

Nothing is imported here, so that the labels file and the settings are checked without JAX (a
``--set`` mistake is reported at once); import a name from the module that defines it
(``from relaff_jax.real.readers import read_cloud``).
"""
