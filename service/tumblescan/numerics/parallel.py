"""Independent calls spread over the cores this process may use.

A job's share of the machine is the thread budget the worker sets for its BLAS and OpenMP pools
(``OMP_NUM_THREADS``: ``tumblescan worker`` gives each worker process cores / workers), else the
process's CPU affinity. With a share of one core, calls run in turn here. With more, they run in
loky's reusable process pool (joblib's executor): the estimators' inner loops are many small
numpy calls that hold the GIL, so threads would not run them side by side. loky starts its
workers by fork + exec (a fork would copy this process's BLAS and OpenCV threads in an unknown
state), does not re-run a script's ``__main__``, keeps the workers between calls and lets them go
after ``IDLE_TIMEOUT_S``. Each worker gets one BLAS thread. If the pool breaks (a worker killed),
the calls run here instead. A daemonic process may not have children (the service's queue workers
are daemonic), so there the calls run in turn as well: the service spreads jobs, not a job's steps.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import TypeVar

T = TypeVar("T")
R = TypeVar("R")

# loky's default. A process that forked this one (a bench's pool worker) waits for its children at exit,
# the pool's workers among them, until they time out.
IDLE_TIMEOUT_S = 10
_ONE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def cores() -> int:
    """The cores this process may use: ``OMP_NUM_THREADS`` when set, else its CPU affinity."""
    env = os.environ.get("OMP_NUM_THREADS", "").strip()
    if env.isdigit() and int(env) > 0:
        return int(env)
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def parallel_map(fn: Callable[[T], R], items: Sequence[T]) -> list[R]:
    """``[fn(x) for x in items]``, the calls spread over ``cores()`` processes when there are more
    than one and at least two items. ``fn`` and the items must pickle (a module-level function,
    or a ``functools.partial`` of one); results come back in order."""
    import multiprocessing

    n = cores()
    if n < 2 or len(items) < 2 or multiprocessing.current_process().daemon:
        return [fn(x) for x in items]
    from loky import get_reusable_executor
    from loky.process_executor import BrokenProcessPool

    try:
        pool = get_reusable_executor(max_workers=n, timeout=IDLE_TIMEOUT_S, env=_ONE_THREAD)
        return list(pool.map(fn, items))
    except BrokenProcessPool:
        return [fn(x) for x in items]
