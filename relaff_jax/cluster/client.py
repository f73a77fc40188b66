"""Start or join a Dask cluster, and check it can run this project's tasks before any work.

Takes an ``Address`` (``address.py``), the output folder and a timeout; ``connect`` is a
context manager giving a ``distributed.Client``:

- ``local:N``: a ``LocalCluster`` of N worker *processes* (one thread each) started with the
  ``spawn`` method, never ``fork`` (JAX deadlocks in a child forked after it started);
- ``tcp://host:port``: the running scheduler there; unreachable within ``timeout`` seconds,
  or no worker joining within it, is a ``UserError``.

Then ``check_workers``: every worker imports the same ``relaff_jax``/``jax`` versions as the
driver (else results would not be bit-identical), writes a probe file into the output folder
(its nearest existing ancestor) and the driver sees it there: the folder must be on a file
system shared by the driver and every worker. Any failure names the workers and the reason.
"""
from __future__ import annotations

import contextlib
import logging
import os
import uuid
from pathlib import Path
from typing import Any, Iterator

from relaff_jax.cluster.address import Address, parse_address
from relaff_jax.errors import UserError
import relaff_jax


def _distributed():
    try:
        import distributed
    except ModuleNotFoundError as e:
        raise UserError("--cluster needs dask.distributed: pip install 'relaff_jax[cluster]' "
                        "(or pip install 'dask[distributed]')") from e
    return distributed


def _has_bokeh() -> bool:
    try:
        import bokeh  # noqa: F401  (only whether it is installed)
    except ModuleNotFoundError:
        return False
    return True


@contextlib.contextmanager
def connect(address: str | Address, folder: str | os.PathLike | None = None, timeout: float = 5.0) -> Iterator[Any]:
    """A ``distributed.Client`` for ``address``, checked (``check_workers``) for ``folder``."""
    addr = address if isinstance(address, Address) else parse_address(address)
    distributed = _distributed()
    import dask

    cluster = None
    with dask.config.set({"distributed.worker.multiprocessing-method": "spawn"}):
        if addr.kind == "local":
            # loopback only (scheduler and dashboard), on free ports: several runs may share a host, and no
            # other machine can reach them; any local user still can (docs/cluster.md, "Security")
            cluster = distributed.LocalCluster(n_workers=addr.workers, threads_per_worker=1, processes=True,
                                               host="127.0.0.1", dashboard_address="127.0.0.1:0",
                                               silence_logs=logging.ERROR)
            client = distributed.Client(cluster)
        else:
            try:
                client = distributed.Client(addr.url, timeout=f"{timeout}s")
            except (OSError, TimeoutError) as e:
                raise UserError(f"--cluster {addr}: cannot reach a Dask scheduler there within {timeout:g} s "
                                f"({type(e).__name__}: {e}); start one with `dask scheduler` or check the address") from None
    try:
        if addr.kind == "remote":
            try:
                client.wait_for_workers(1, timeout=timeout)
            except TimeoutError:
                raise UserError(f"--cluster {addr}: the scheduler has no worker (none joined within {timeout:g} s); "
                                "start some with `dask worker " + addr.url + "`") from None
        if folder is not None:
            check_workers(client, folder)
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def dashboard(client: Any) -> str | None:
    """The Dask dashboard's URL, or None when the scheduler serves none (bokeh not installed
    where the scheduler runs: its HTTP server then has no dashboard pages)."""
    with contextlib.suppress(Exception):
        if not client.run_on_scheduler(_has_bokeh):
            return None
        info = client.scheduler_info()
        if "dashboard" in info.get("services", {}):
            return client.dashboard_link
    return None


def describe(client: Any) -> str:
    """One line: workers, threads and the dashboard address (or how to get one)."""
    info = client.scheduler_info()
    workers = info.get("workers", {})
    threads = sum(w.get("nthreads", 1) for w in workers.values())
    link = dashboard(client)
    where = f"dashboard {link}" if link else "no dashboard (pip install bokeh for one)"
    return f"cluster {info.get('address', '?')}: {len(workers)} workers, {threads} threads; {where}"


def nthreads(client: Any) -> int:
    """Task slots of the cluster (sum of worker threads), at least 1."""
    return max(1, sum(client.nthreads().values()))


def probe_folder(folder: str, tag: str, remove: bool) -> dict:
    """Worker side of ``check_workers``: versions, and write (or remove) this worker's probe
    file ``folder/TAG-HOST-PID.tmp``; returns its ``name`` and any ``error``."""
    import socket

    import jax

    name = f"{tag}-{socket.gethostname()}-{os.getpid()}.tmp"
    out = {"relaff_jax": relaff_jax.__version__, "jax": jax.__version__, "error": None, "name": name}
    path = Path(folder) / name
    try:
        if remove:
            path.unlink(missing_ok=True)
        else:
            with open(path, "w") as f:
                f.write(f"{os.getpid()}\n")
    except OSError as e:
        out["error"] = f"{e.strerror or e}"
    return out


def _existing_ancestor(folder: Path) -> Path:
    probe = folder.absolute()
    while not probe.exists() and probe.parent != probe:
        probe = probe.parent
    return probe


def check_workers(client: Any, folder: str | os.PathLike) -> None:
    """``UserError`` unless every worker has our versions and can write ``folder`` (or its
    nearest existing ancestor) on a file system the driver sees."""
    import jax

    where = _existing_ancestor(Path(folder))
    tag = f".relaff-probe-{uuid.uuid4().hex[:12]}"
    got = client.run(probe_folder, str(where), tag, False)  # one round trip to every worker
    try:
        bad_version = {w: r for w, r in got.items() if (r["relaff_jax"], r["jax"]) != (relaff_jax.__version__, jax.__version__)}
        if bad_version:
            w, r = next(iter(bad_version.items()))
            raise UserError(f"worker {w} runs relaff_jax {r['relaff_jax']} / jax {r['jax']}, the driver "
                            f"{relaff_jax.__version__} / {jax.__version__}: install the same versions everywhere")
        failed = {w: r["error"] for w, r in got.items() if r["error"]}
        if failed:
            listing = "; ".join(f"{w}: {e}" for w, e in failed.items())
            raise UserError(f"{folder}: {len(failed)} of {len(got)} cluster workers cannot write in {where} ({listing}); "
                            "the output folder must be writable by every worker")
        unseen = [w for w, r in got.items() if not (where / r["name"]).exists()]
        if unseen:
            raise UserError(f"{folder}: files written in {where} by workers {unseen} are not visible here; the output "
                            "folder must be on a file system shared by the driver and every worker (docs/cluster.md)")
    finally:
        with contextlib.suppress(Exception):
            client.run(probe_folder, str(where), tag, True)
