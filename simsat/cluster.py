"""The Dask client every sweep uses: an existing scheduler by address, or a local cluster of processes."""
from __future__ import annotations

import logging
import os
from contextlib import contextmanager

__all__ = ["dask_client"]


@contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None):
    """A Dask client: on ``scheduler`` (an address), else on a new local cluster of ``workers`` processes."""
    from distributed import Client, LocalCluster

    if scheduler:
        client = Client(scheduler, timeout="20s")
        try:
            yield client
        finally:
            client.close()
        return
    n = int(workers or os.cpu_count() or 1)
    with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                      silence_logs=logging.CRITICAL) as cluster, Client(cluster) as client:
        yield client
