"""``relaff reproduce``: the whole study in one resumable command.

- ``folder.py``: the run log and the seeds of every stage (the folder's layout is
  ``stages.protocol.Paths``);
- ``progress.py``: the progress line and its time estimate;
- ``run.py``: ``reproduce()``, which composes the four stages of ``relaff_jax.stages``, and
  ``status()`` of a folder.
"""
from relaff_jax.constants import ACTIONS, SPACES, STAGES
from relaff_jax.report.status import STAMP as REPORT_STAMP
from relaff_jax.reproduce.folder import FORMAT, FORMAT_VERSION, RUN_LOG, Paths, ReproduceError, seeds
from relaff_jax.reproduce.progress import COST, Progress, estimate_seconds, fmt_time
from relaff_jax.reproduce.run import check_config, reproduce, status
from relaff_jax.config import PRESETS, preset
from relaff_jax.stages.protocol import Hooks

__all__ = ["ACTIONS", "SPACES", "STAGES", "REPORT_STAMP", "FORMAT", "FORMAT_VERSION", "RUN_LOG", "PRESETS",
           "Paths", "ReproduceError", "COST", "Hooks", "Progress", "check_config", "estimate_seconds", "fmt_time",
           "preset", "reproduce", "seeds", "status"]
