"""Run many independent simulations through a ``concurrent.futures``-style executor.

Local processes by default; a Dask cluster when a scheduler address is given (``dask.distributed``
is an optional extra: ``pip install 'foveatrack[dask]'``).  Results come back as they finish, with
a progress bar, and the caller may stop early.  Used by the coverage map (paper Fig. 7) and the
accuracy-vs-time study.
"""

from __future__ import annotations

import contextlib
import os
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from typing import Any, Callable, Iterable, Iterator

from tqdm import tqdm

from foveatrack.errors import UserError


@contextlib.contextmanager
def make_executor(scheduler: str | None = None, workers: int | None = None) -> Iterator[Executor]:
    """An executor: local processes, or the Dask cluster at ``scheduler`` (``tcp://host:port``)."""
    if scheduler is None:
        n = workers or max(1, (os.cpu_count() or 1))
        with ProcessPoolExecutor(max_workers=n) as ex:
            yield ex
        return
    try:
        from distributed import Client
    except ImportError:  # pragma: no cover - depends on the installed extras
        raise UserError("--scheduler needs dask.distributed: pip install 'foveatrack[dask]'") from None
    try:
        client = Client(scheduler, timeout="10s")
    except (OSError, TimeoutError) as exc:
        raise UserError(f"--scheduler {scheduler}: cannot reach a Dask scheduler there ({exc})") from None
    try:
        yield client.get_executor()
    finally:
        client.close()


def run_tasks(fn: Callable[[Any], Any], tasks: Iterable[Any], executor: Executor, desc: str = "tasks",
              progress: bool = True) -> list[tuple[Any, Any]]:
    """``[(task, fn(task)), ...]`` in completion order, with a progress bar on stderr."""
    tasks = list(tasks)
    futures = {executor.submit(fn, t): t for t in tasks}
    out = []
    with tqdm(total=len(tasks), desc=desc, disable=not progress, unit="run") as bar:
        for fut in as_completed(futures):
            out.append((futures[fut], fut.result()))
            bar.update(1)
    return out
