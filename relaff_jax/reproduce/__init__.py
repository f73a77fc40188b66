"""``relaff reproduce``: the whole study in one resumable command.

- ``folder.py``: the run folder's layout, the run log, the seeds of every stage;
- ``stage.py``: the contract of a stage (``status``, ``progress``, ``run``) and ``Run``;
- ``generate.py``, ``features.py``, ``experiment.py``, ``report.py``: the four stages;
- ``progress.py``: the progress line and its time estimate;
- ``run.py``: ``reproduce()``, which composes the stages, and ``status()`` of a folder.
"""
from relaff_jax.constants import ACTIONS, SPACES, STAGES
from relaff_jax.report.status import STAMP as REPORT_STAMP
from relaff_jax.reproduce.features import default_feature_factory, feature_config
from relaff_jax.reproduce.folder import FORMAT, FORMAT_VERSION, RUN_LOG, Paths, ReproduceError, seeds
from relaff_jax.reproduce.generate import default_rollout_factory
from relaff_jax.reproduce.progress import COST, Progress, estimate_seconds, fmt_time
from relaff_jax.reproduce.run import check_config, reproduce, status
from relaff_jax.reproduce.stage import Run, Status

__all__ = ["ACTIONS", "SPACES", "STAGES", "REPORT_STAMP", "FORMAT", "FORMAT_VERSION", "RUN_LOG",
           "Paths", "ReproduceError", "Run", "Status", "COST", "Progress", "check_config", "default_feature_factory",
           "default_rollout_factory", "estimate_seconds", "feature_config", "fmt_time", "reproduce",
           "seeds", "status"]
