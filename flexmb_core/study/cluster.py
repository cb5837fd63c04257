"""The Dask cluster every study verb runs on (``flexmb sweep``, ``calibrate``, ``tune``, ``bench``,
``replay DIR``): an in-process ``LocalCluster`` of worker processes on 127.0.0.1 by default, or the
scheduler a user names with ``--scheduler ADDRESS`` (a cluster started with ``dask scheduler`` /
``dask worker``, ``dask-jobqueue`` or ``dask-kubernetes``).

Dask is imported inside :func:`connect` only: the rest of flexmb works without it.
"""

from __future__ import annotations

import logging
import os
from contextlib import contextmanager
from typing import Any

from ..errors import FlexmbError, excerpt


class ClusterError(FlexmbError):
    """Dask is missing or the scheduler cannot be reached."""


def default_workers() -> int:
    """One worker process per core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:                      # not Linux
        return max(1, os.cpu_count() or 1)


@contextmanager
def connect(scheduler: Any = None, workers: int | None = None, verb: str = "flexmb sweep"):
    """A ``dask.distributed.Client``: the given one, one connected to ``scheduler`` (an address),
    or one on a new ``LocalCluster`` of ``workers`` processes bound to 127.0.0.1."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise ClusterError(f"{verb} runs on Dask distributed: install the extra [cluster] "
                           "(pip install 'flexmb[cluster]', or dask and distributed)") from None
    if isinstance(scheduler, Client):
        yield scheduler
        return
    if scheduler:
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError) as exc:
            raise ClusterError(f"--scheduler {excerpt(scheduler)}: cannot connect ({exc})") from None
        except ValueError as exc:       # distributed's parse of the address (no port, no host)
            raise ClusterError(f"--scheduler {excerpt(scheduler)}: expected a scheduler address such as "
                               f"tcp://127.0.0.1:8786 ({exc})") from None
        try:
            yield client
        finally:
            client.close()
        return
    # CRITICAL: a task that raises (a calibration run whose scene the fit's step made invalid) is
    # reported by flexmb in one line; the worker's own ERROR record would print its traceback first.
    # A lost worker or task still reaches the client as an exception (sweep: error_kind 'lost').
    cluster = LocalCluster(n_workers=workers or default_workers(), threads_per_worker=1, processes=True,
                           host="127.0.0.1", dashboard_address="127.0.0.1:0",
                           worker_dashboard_address="127.0.0.1:0", silence_logs=logging.CRITICAL)
    client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()
