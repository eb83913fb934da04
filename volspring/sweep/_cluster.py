"""Where runs go: a Dask cluster of worker processes (local, or any running scheduler), or this process.

:func:`sweep_client` makes the client: a new local cluster of worker processes, one BLAS thread each
(:data:`BLAS_ENVIRONMENT`), or a connection to a running scheduler. :func:`finishing` submits calls as tasks and
yields each as it finishes, cancelling the others when the caller stops (an interruption leaves no task running
on a shared cluster); :func:`run_calls` runs independent calls and returns their results, in this process or on
a cluster. Sweeps (:func:`volspring.sweep.run_sweep`) and the validation report (``volspring validate
--workers``) both send their runs through here.

Examples
--------
>>> run_calls({"a": (pow, (2, 10), {}), "b": (divmod, (7, 2), {})})
{'a': 1024, 'b': (3, 1)}
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from distributed import Client

__all__ = ["BLAS_ENVIRONMENT", "finishing", "run_calls", "sweep_client"]

logger = logging.getLogger(__name__)

#: Environment of the local cluster's workers: one BLAS/OpenMP thread each, so that N workers use N cores
#: instead of fighting over them (and every run's arithmetic is the serial run's).
BLAS_ENVIRONMENT = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}

#: A call: ``(function, args, kwargs)``, run as ``function(*args, **kwargs)``.
Call = tuple


@contextmanager
def sweep_client(*, workers: int | None = None, scheduler: str | None = None) -> Iterator[Client]:
    """A Dask client for :func:`run_sweep`: on a new local cluster, or on the scheduler at ``scheduler``.

    Parameters
    ----------
    workers : int, optional
        Worker processes of the local cluster, one thread each with :data:`BLAS_ENVIRONMENT` (default: the CPU
        count). Not used with ``scheduler``.
    scheduler : str, optional
        The address of a running scheduler (``tcp://host:8786``, started by ``dask scheduler``); its workers are
        the cluster's own (start them with ``--nthreads 1`` and ``OMP_NUM_THREADS=1``).

    Yields
    ------
    distributed.Client
        Closed (and the local cluster shut down) when the block ends.
    """
    import dask
    from distributed import Client, LocalCluster

    if scheduler is not None:
        with Client(scheduler) as client:
            client.run(_warm_up)
            yield client
        return
    workers = (os.cpu_count() or 1) if workers is None else int(workers)
    if workers < 1:
        raise ValueError(f"workers = {workers} is not >= 1")
    # Dask's statistical profiler samples the running task every 10 ms: 5-10% of a run's time, for a profile
    # nobody reads here. The workers take the configuration as it is when they start.
    with dask.config.set({"distributed.worker.profile.enabled": False}), \
            LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0",
                         env=dict(BLAS_ENVIRONMENT), silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
        client.run(_warm_up)
        logger.info("local cluster of %d worker processes; its dashboard: %s", workers, client.dashboard_link)
        yield client


def _warm_up() -> None:
    """Import what a run needs (1-3 s: scipy, pyamg, gmsh), on every worker at once as the cluster starts,
    rather than in the first run of each."""
    import importlib

    for name in ("volspring.sweep._measure", "volspring.scene_file._assemble", "volspring.simulate",
                 "volspring.integrators.implicit", "meshing.tetrahedralize", "pyamg"):
        importlib.import_module(name)


def finishing(client: Client, calls: Mapping[str, Call], *, prefix: str = "volspring") -> Iterator[tuple[str, Any]]:
    """Submit every call as a Dask task on ``client``; yield ``(key, future)`` as each finishes.

    Parameters
    ----------
    client : distributed.Client
    calls : mapping of str to (function, args, kwargs)
        Independent calls; each task's Dask key is ``PREFIX-KEY``.
    prefix : str

    Yields
    ------
    (str, distributed.Future)
        Finished (done, failed or lost); ``future.result()`` returns or raises. Released after the caller's turn.
        When the caller stops iterating (an exception, Ctrl-C), the tasks not yet finished are cancelled.
    """
    from distributed import as_completed

    futures = {client.submit(function, *args, key=f"{prefix}-{key}", pure=False, **kwargs): key
               for key, (function, args, kwargs) in calls.items()}
    try:
        for future in as_completed(futures):
            try:
                yield futures[future], future
            finally:
                future.release()
    finally:
        client.cancel(list(futures))


def run_calls(calls: Mapping[str, Call], *, client: Client | None = None,
              on_result: Callable[[str, Any, int, int], None] | None = None) -> dict:
    """Run independent calls in this process (``client=None``, in order) or as tasks on ``client``'s cluster.

    Parameters
    ----------
    calls : mapping of str to (function, args, kwargs)
    client : distributed.Client, optional
    on_result : callable, optional
        ``on_result(key, result, done, total)`` as each call returns.

    Returns
    -------
    dict
        key -> result, in the order of ``calls``.

    Raises
    ------
    Exception
        The first exception a call raises (in the order they finish), after the other tasks are cancelled.
    """
    results = {}
    if client is None:
        for key, (function, args, kwargs) in calls.items():
            results[key] = function(*args, **kwargs)
            if on_result is not None:
                on_result(key, results[key], len(results), len(calls))
    else:
        for key, future in finishing(client, calls):
            results[key] = future.result()
            if on_result is not None:
                on_result(key, results[key], len(results), len(calls))
    return {key: results[key] for key in calls}
