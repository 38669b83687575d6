"""One executor for every fan-out of independent tasks (campaigns, identification, sweeps, comparisons).

Tasks run in this process (``workers=1``), in local worker processes
(``workers>1``), or on dask.distributed (``scheduler="local:N"`` starts a
LocalCluster with N worker processes; any other string is the address of an
existing scheduler). Every task must carry its own seed: results never depend
on where or in which order the tasks ran.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
import logging
from dataclasses import dataclass
from typing import Any
from vivbench.core.errors import InputError

__all__ = ["Outcome", "run_tasks", "parse_scheduler"]


@dataclass(frozen=True)
class Outcome:
    """The result of task ``index``: ``value`` on success, ``error`` (one line) on failure."""

    index: int
    value: Any = None
    error: str | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


def _one_line(exc: BaseException) -> str:
    return " ".join(f"{type(exc).__name__}: {exc}".split())


def parse_scheduler(text: str | None) -> tuple[str, int | str | None]:
    """``None`` -> ("processes", None); ``"local:N"`` -> ("local", N); else ("address", text)."""
    if text is None or text == "":
        return "processes", None
    if text.startswith("local:"):
        try:
            n = int(text.split(":", 1)[1])
        except ValueError:
            n = 0
        if n < 1:
            raise InputError(f"scheduler {text!r}: expected local:N with N >= 1 worker processes, or a scheduler address")
        return "local", n
    return "address", text


def _local_processes(func, tasks, workers) -> Iterator[Outcome]:
    if workers <= 1:
        for i, task in enumerate(tasks):
            try:
                yield Outcome(i, value=func(task))
            except Exception as exc:  # one failing task must not sink the others
                yield Outcome(i, error=_one_line(exc))
        return
    pool = ProcessPoolExecutor(max_workers=workers)
    try:
        futures = {pool.submit(func, task): i for i, task in enumerate(tasks)}
        for fut in as_completed(futures):
            i = futures[fut]
            try:
                yield Outcome(i, value=fut.result())
            except Exception as exc:
                yield Outcome(i, error=_one_line(exc))
    finally:
        # A consumer that stops early (an interrupt, a closed generator) must not
        # wait for the queued tasks to run: cancel them, let the running ones end.
        pool.shutdown(wait=True, cancel_futures=True)


def _guarded(func, task):
    """Run on a dask worker: a task's exception comes back as a value.

    The worker would otherwise log every failing task with its traceback
    ("Compute Failed") to its stderr; failures are reported once, as Outcomes.
    """
    try:
        return True, func(task)
    except Exception as exc:
        return False, _one_line(exc)


def _dask(func, tasks, kind, arg) -> Iterator[Outcome]:
    try:
        from dask.distributed import Client, LocalCluster, as_completed as dask_completed
    except ImportError as exc:  # pragma: no cover - dask is in the test extra
        raise InputError("dask.distributed is not installed: pip install 'vivbench[dask]'") from exc
    cluster = None
    futures = []
    if kind == "local":
        # Worker processes with one thread each, on loopback, so nothing leaves the machine.
        cluster = LocalCluster(n_workers=arg, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None, silence_logs=logging.CRITICAL)
        client = Client(cluster)
    else:
        client = Client(arg, timeout="10s")
    try:
        futures = [client.submit(_guarded, func, task, pure=False) for task in tasks]
        index = {f.key: i for i, f in enumerate(futures)}
        for fut in dask_completed(futures):
            i = index[fut.key]
            try:
                ok, value = fut.result()
            except Exception as exc:  # the task never ran to an answer (e.g. its worker died)
                yield Outcome(i, error=_one_line(exc))
            else:
                yield Outcome(i, value=value) if ok else Outcome(i, error=value)
            fut.release()
    finally:
        # On an early stop the scheduler must not run what nobody will collect.
        pending = [f for f in futures if not f.done()]
        if pending:
            client.cancel(pending)
        client.close()
        if cluster is not None:
            cluster.close()


def run_tasks(func: Callable[[Any], Any], tasks: Sequence[Any], *, workers: int = 1,
              scheduler: str | None = None) -> Iterator[Outcome]:
    """Run ``func(task)`` for every task and yield an :class:`Outcome` as each finishes.

    Parameters
    ----------
    func : picklable top-level function of one argument
    tasks : sequence of picklable task descriptions (each with its own seed)
    workers : local worker processes when ``scheduler`` is None (1: in this process)
    scheduler : None, ``"local:N"`` or a dask scheduler address (``tcp://host:port``)

    Yields
    ------
    Outcome, in completion order; ``Outcome.index`` is the task's position.
    A task that raises yields an Outcome with ``error`` set; the others run on.
    """
    kind, arg = parse_scheduler(scheduler)
    if workers < 1:
        raise InputError(f"workers must be >= 1, got {workers}")
    if len(tasks) == 0:
        return  # no worker processes or cluster for nothing (a resumed run that is complete)
    if kind == "processes":
        yield from _local_processes(func, tasks, workers)
    else:
        yield from _dask(func, tasks, kind, arg)
