"""Running the heavy stages on a Dask cluster (``--cluster ADDRESS``; docs/cluster.md).

The stages are already cut into independent, atomically written pieces (dataset chunks,
feature chunks, sweep blocks); this package runs them as ``dask.distributed`` tasks:

- ``address.py``: ``local:N`` / ``tcp://host:port`` parsed into an ``Address``;
- ``client.py``: ``connect`` starts a ``LocalCluster`` (spawned workers) or joins a scheduler,
  and checks versions and that every worker can write the output folder, before any work;
- ``remote.py``: ``Remote``, a function shipped as its recipe and built once per worker;
- ``tasks.py``: ``Ordered`` (pieces in index order, bounded window) and ``map_calls``.

``dask`` is an optional dependency (``pip install 'relaff_jax[cluster]'``), imported only
when a cluster is used. The client travels one way: as the ``client`` argument of the stage
functions (``generate_dataset``, ``add_features``, ``run_experiment``, ``run_parallel``).
"""
from relaff_jax.cluster.address import Address, parse_address
from relaff_jax.cluster.client import check_workers, connect, dashboard, describe, nthreads
from relaff_jax.cluster.remote import Remote
from relaff_jax.cluster.tasks import Ordered, cancel_all, map_calls

__all__ = ["Address", "Ordered", "Remote", "cancel_all", "check_workers", "connect", "dashboard", "describe",
           "map_calls", "nthreads", "parse_address"]
