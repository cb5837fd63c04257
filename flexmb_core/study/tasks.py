"""Running a list of tasks on Dask and getting the results back in list order — what ``flexmb tune``,
``flexmb bench --workers N`` and ``flexmb replay DIR`` share (``flexmb sweep`` has its own, resumable
loop in :mod:`.sweep`).

The client comes from :func:`.cluster.connect`. Every function here takes it as an argument and
imports Dask inside, so the rest of flexmb works without Dask.

Timing on a cluster: a run's wall time is only comparable with another's when both ran alone on
a core. :func:`run_alone` runs one task at a time on one chosen worker (:func:`timing_worker`),
which is how the study verbs re-time the runs whose speed decides something.
"""

from __future__ import annotations

import uuid
from typing import Any, Callable, Sequence


def cluster_facts(client: Any) -> tuple[str, int]:
    """(scheduler address, number of worker threads) of a connected client."""
    return str(client.scheduler.address), len(client.nthreads())


def run_all(client: Any, fn: Callable, items: Sequence, *, name: str,
            on_result: Callable[[int, Any], None] | None = None) -> list:
    """``[fn(x) for x in items]``, each call a Dask task (any worker, all at once).

    ``on_result(i, result)`` is called as each task finishes (completion order); the list returned
    is in ``items`` order. A task that raises re-raises here (the other tasks are cancelled), as the
    same call would in a loop; so does a task the cluster lost (a worker died more often than
    ``distributed.scheduler.allowed-failures``). Ctrl-C cancels the tasks and re-raises.
    """
    from dask.distributed import as_completed

    tag = uuid.uuid4().hex[:8]
    futures = [client.submit(fn, x, key=f"{name}-{tag}-{i}", pure=False) for i, x in enumerate(items)]
    index = {f.key: i for i, f in enumerate(futures)}
    out: list = [None] * len(futures)
    try:
        for fut, res in as_completed(futures, with_results=True):
            i = index[fut.key]
            out[i] = res
            fut.release()
            if on_result is not None:
                on_result(i, res)
    except BaseException:
        client.cancel(futures)
        raise
    return out


def timing_worker(client: Any) -> str:
    """The address of the worker the re-timed runs go to (the first by address: stable within a run)."""
    workers = sorted(client.scheduler_info()["workers"])
    if not workers:
        raise RuntimeError("the Dask cluster has no workers")
    return workers[0]


def run_alone(client: Any, fn: Callable, item: Any, worker: str, *, name: str) -> Any:
    """``fn(item)`` on ``worker`` while the caller runs nothing else there: the caller waits for it.

    If that worker dies, the scheduler may run the task elsewhere (still alone as far as the caller
    is concerned).
    """
    fut = client.submit(fn, item, key=f"{name}-{uuid.uuid4().hex[:8]}", pure=False, workers=[worker],
                        allow_other_workers=True)
    try:
        return fut.result()
    finally:
        fut.release()
