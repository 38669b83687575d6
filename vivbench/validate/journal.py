"""The journal of a sweep: one JSON line per finished task, and the table rebuilt from it.

Lines are appended and flushed to disk as tasks finish, so a sweep killed at
any moment leaves every finished task on disk and at most one half-written
last line. On start the journal is read back: lines that are not complete,
valid records (the half-written line of a kill, anything corrupt) and failed
tasks are dropped, and the journal is rewritten without them before anything
is appended, so a new line never continues a broken one.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any

from collections.abc import Callable, Sequence
from contextlib import closing

from vivbench.core.errors import InputError
from vivbench.core.parallel import run_tasks
from vivbench.io.netcdf import atomic_path

__all__ = ["load", "append", "write_table", "format_value", "check_record", "run_journalled",
           "counting_progress", "task_directory"]


def _valid(record: Any, n_tasks: int, columns) -> bool:
    if not isinstance(record, dict) or record.get("ok") not in (True, False):
        return False
    task_id = record.get("task_id")
    if isinstance(task_id, bool) or not isinstance(task_id, int) or not 0 <= task_id < n_tasks:
        return False
    row = record.get("row")
    return isinstance(row, dict) and set(columns) <= set(row) and row.get("task_id") == task_id


def load(path: Path, *, n_tasks: int, columns) -> tuple[dict[int, dict], int]:
    """Finished tasks of a journal, repairing it on disk when needed.

    Returns
    -------
    rows : task id -> table row, for the tasks that finished without error
    dropped : number of corrupt or half-written lines dropped
    """
    if not path.exists():
        return {}, 0
    data = path.read_bytes()
    lines = data.split(b"\n")
    # Everything after the last newline is a line the writer did not finish.
    complete, tail = lines[:-1], lines[-1]
    dropped = 1 if tail.strip() else 0
    rows: dict[int, dict] = {}
    keep: list[bytes] = []
    for line in complete:
        if not line.strip():
            continue
        try:
            record = json.loads(line)
        except (json.JSONDecodeError, UnicodeDecodeError):
            dropped += 1
            continue
        if not _valid(record, n_tasks, columns):
            dropped += 1
            continue
        if record["ok"] and record["task_id"] not in rows:
            rows[record["task_id"]] = record["row"]
            keep.append(line)
    if len(keep) != len(complete) or tail:
        # Failed tasks are retried, so their lines go too; rewrite before appending.
        with atomic_path(path) as tmp:
            tmp.write_bytes(b"".join(line + b"\n" for line in keep))
    return rows, dropped


def append(path: Path, task_id: int, ok: bool, row: dict) -> None:
    """Append one record and push it to disk before returning."""
    line = json.dumps({"task_id": task_id, "ok": ok, "row": row}, sort_keys=True, allow_nan=True) + "\n"
    with path.open("a", encoding="utf-8") as fh:
        fh.write(line)
        fh.flush()
        os.fsync(fh.fileno())


def format_value(value: Any) -> str:
    """Table text of a value: floats to 6 significant digits (NaN as ``nan``), the rest as is."""
    if isinstance(value, float):
        return "nan" if math.isnan(value) else format(value, ".6g")
    return str(value)


def write_table(path: Path, rows: dict[int, dict], columns) -> None:
    """Write the rows sorted by task id as CSV, atomically."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(columns)
    for task_id in sorted(rows):
        writer.writerow([format_value(rows[task_id].get(c, "")) for c in columns])
    with atomic_path(path) as tmp:
        tmp.write_text(buf.getvalue(), encoding="utf-8")


def check_record(record: Path, fingerprint: str, config: dict, refusal: str) -> None:
    """Tie an output directory to one run configuration.

    Writes ``record`` (JSON: the fingerprint and the configuration) on the first run; on a later
    run, a record with another fingerprint (or an unreadable one) raises InputError
    ``"{record}: {refusal}"``, so that a journal never mixes the rows of two configurations.
    """
    if record.exists():
        try:
            old = json.loads(record.read_text()).get("fingerprint")
        except (json.JSONDecodeError, AttributeError):
            old = None
        if old != fingerprint:
            raise InputError(f"{record}: {refusal}")
        return
    text = json.dumps({"fingerprint": fingerprint, "config": config}, indent=1, sort_keys=True) + "\n"
    with atomic_path(record) as tmp:
        tmp.write_text(text)


def run_journalled(func: Callable[[Any], dict], tasks: Sequence[Any], journal: Path, done: dict[int, dict], *,
                   task_id: Callable[[Any], int], failed_row: Callable[[Any], dict], workers: int = 1,
                   scheduler: str | None = None, progress: Callable[[], None] | None = None
                   ) -> tuple[list[int], dict[int, str]]:
    """Run ``func`` on every task (:func:`vivbench.core.parallel.run_tasks`) and journal each outcome as it comes.

    Parameters
    ----------
    func : picklable top-level function of one task, returning the task's row (a dict)
    tasks : the pending tasks
    journal : the journal file (:func:`append`)
    done : task id -> row; finished tasks are added to it
    task_id : the id of a task
    failed_row : the journal row of a failed task (beside ``task_id`` and ``error``)
    workers, scheduler : where the tasks run
    progress : called after every task

    Returns
    -------
    computed : ids of the tasks that finished; failures : id -> one-line error (retried by the next run)
    """
    computed: list[int] = []
    failures: dict[int, str] = {}
    with closing(run_tasks(func, tasks, workers=workers, scheduler=scheduler)) as outcomes:
        for outcome in outcomes:
            task = tasks[outcome.index]
            tid = task_id(task)
            if outcome.ok:
                row = {"task_id": tid, **outcome.value}
                done[tid] = row
                computed.append(tid)
            else:
                row = {"task_id": tid, **failed_row(task), "error": outcome.error}
                failures[tid] = outcome.error
            append(journal, tid, outcome.ok, row)
            if progress is not None:
                progress()
    return computed, failures


def counting_progress(progress: Callable[[int, int], None], start: int, total: int) -> Callable[[], None]:
    """A callback for :func:`run_journalled` that calls ``progress(n_done, total)``, counting from ``start``."""
    count = [start]

    def advance() -> None:
        count[0] += 1
        progress(count[0], total)

    return advance


def task_directory(work_root: str | None, prefix: str) -> Path:
    """A new scratch directory for one task: under ``work_root`` (created) or the system's temporary one."""
    if work_root is not None:
        Path(work_root).mkdir(parents=True, exist_ok=True)
    return Path(tempfile.mkdtemp(prefix=prefix, dir=work_root))
