"""Benchmark episodes on a Dask distributed cluster (``docs/dask.md``).

`dask_executor` connects to a running scheduler (or starts a local cluster of worker
processes) and yields a `concurrent.futures.Executor` for
`hptrack.experiments.benchmark.run_benchmark`. The run itself does not change: episodes
are claimed in the client's SQLite store, run on the workers and stored on the client as each
one finishes, so resuming and sharing work are as with the local process pool. Workers import
hptrack themselves (``run_one`` travels by reference) and use its on-disk numba cache.

Dask is an optional extra (``pip install 'hptrack[dask]'``) imported only here, inside the
functions.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Iterator
from concurrent.futures import Executor
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass

from hptrack.interface import InputError

logger = logging.getLogger(__name__)

SCHEDULER_TIMEOUT_S = 10.0
"""Default wait for a scheduler to answer, s."""
MAX_SCHEDULER_TIMEOUT_S = 3600.0
"""Longest wait for a scheduler to answer, s (an hour; longer is a hang, not a wait)."""


@dataclass(frozen=True)
class DaskPool:
    """A connected Dask cluster.

    Attributes:
        executor: a `concurrent.futures.Executor` running tasks on the cluster.
        threads: the worker threads the cluster had when connected (0 if no worker has
            joined yet).
        address: the scheduler's address.
    """

    executor: Executor
    threads: int
    address: str


def check_dask_options(
    scheduler: str | None, local_workers: int | None, timeout_s: float = SCHEDULER_TIMEOUT_S
) -> None:
    """Refuse contradictory or impossible Dask options, and a missing Dask, before any work.

    Raises:
        InputError: both options, ``local_workers < 1``, a timeout that is not positive, or
            Dask not installed (one line naming the option and its value).
    """
    if scheduler is not None and local_workers is not None:
        raise InputError(
            f"give --scheduler ({scheduler}) or --dask-local ({local_workers}), not both"
        )
    if scheduler is None and local_workers is None:
        return
    option = (
        f"--scheduler {scheduler}" if scheduler is not None else f"--dask-local {local_workers}"
    )
    if local_workers is not None and local_workers < 1:
        raise InputError(
            f"--dask-local must be a positive number of worker processes, got {local_workers}"
        )
    if scheduler is not None and not scheduler.strip():
        raise InputError(
            f"--scheduler expects a scheduler address such as tcp://host:8786, got {scheduler!r}"
        )
    if not 0 < timeout_s <= MAX_SCHEDULER_TIMEOUT_S:
        raise InputError(
            "--scheduler-timeout must be a positive number of seconds of at most "
            f"{MAX_SCHEDULER_TIMEOUT_S:g}, got {timeout_s}"
        )
    try:
        import distributed  # noqa: F401
    except ImportError as err:
        raise InputError(
            f"{option}: Dask is not installed ({err}); pip install 'hptrack[dask]'"
        ) from None


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split())


def _probe(address: str, timeout_s: float) -> None:
    """Open and close one connection to the scheduler (a clean failure, unlike a half-made
    ``Client``, whose clean-up times out again at exit)."""
    from distributed.comm import connect
    from distributed.security import Security

    async def probe() -> None:
        comm = await connect(address, timeout=timeout_s, **Security().get_connection_args("client"))
        await comm.close()

    asyncio.run(probe())


@contextmanager
def dask_executor(
    scheduler: str | None = None,
    local_workers: int | None = None,
    timeout_s: float = SCHEDULER_TIMEOUT_S,
) -> Iterator[DaskPool]:
    """Connect to the Dask scheduler at ``scheduler`` (e.g. ``tcp://host:8786``), or start a
    local cluster of ``local_workers`` processes with one thread each on 127.0.0.1 (no
    dashboard) and close it on exit.

    Raises:
        InputError: bad options (`check_dask_options`), or no scheduler at ``scheduler``
            answering within ``timeout_s`` seconds.
    """
    check_dask_options(scheduler, local_workers, timeout_s)
    if scheduler is None and local_workers is None:
        raise ValueError("give a scheduler address or a number of local workers")
    from distributed import Client, LocalCluster

    with ExitStack() as stack:
        if scheduler is not None:
            try:
                _probe(scheduler, timeout_s)
            except (ValueError, TypeError) as err:
                raise InputError(
                    f"--scheduler {scheduler}: not a Dask scheduler address such "
                    f"as tcp://host:8786 ({_one_line(err)})"
                ) from None
            except OSError as err:
                raise InputError(
                    f"--scheduler {scheduler}: no Dask scheduler answered within "
                    f"{timeout_s:g} s ({_one_line(err)})"
                ) from None
            client = stack.enter_context(Client(scheduler, timeout=timeout_s, set_as_default=False))
        else:
            cluster = stack.enter_context(
                LocalCluster(
                    n_workers=local_workers,
                    threads_per_worker=1,
                    processes=True,
                    host="127.0.0.1",
                    dashboard_address=None,
                )
            )
            client = stack.enter_context(Client(cluster, set_as_default=False))
        threads = sum(client.nthreads().values())
        logger.info("Dask scheduler %s: %d worker threads", client.scheduler.address, threads)
        # pure=False: every submission is a task of its own, never merged with a cancelled one
        yield DaskPool(client.get_executor(pure=False), threads, client.scheduler.address)
