"""The four stages of the study, each one module that both its command and ``relaff
reproduce`` call.

- ``protocol.py``: the contract (``Stage``: ``NAME``, ``status``, ``progress``, ``run``),
  ``Status``, ``Run`` (the state a ``reproduce`` run passes along), ``Paths`` (the run folder's
  layout) and ``Hooks`` (stand-ins for the simulation and the perception);
- ``generate.py``: one balanced dataset per action (``relaff generate``: ``generate_one``);
- ``features.py``: PCA and RHF features of each dataset (``relaff features``: ``add_features``);
- ``experiment.py``: the learning and bootstrapping sweeps (``relaff experiment``:
  ``experiment_folder``);
- ``report.py``: Table II, findings, figures and the report document (``relaff report``:
  ``report_folder``).

The computation stays in its package (``sim``, ``data``, ``perception``, ``learn``,
``report``); a stage module reads the settings from the config tree, calls that package and
writes the folder's config record. ``relaff_jax.reproduce`` composes the stages. Nothing is
imported here, so that a command checks its arguments before the heavy packages load.
"""
