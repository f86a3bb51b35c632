"""Campaign engine: many independent tasks run serially, on local processes or on a Ray cluster.

A *task* is a function named ``"package.module:function"`` and a *key*, the JSON-serialisable
keyword arguments that define its result (controller, track, seed, options; or a training seed
and its hyper-parameters). Everything random in a task must be drawn from its key, never from
its position in a queue or from the worker that runs it: then a parallel or distributed
campaign returns, per task, exactly what the serial run returns.

:func:`run_tasks` runs a list of tasks with one of three executors:

* ``serial``: one after the other in this process;
* ``process``: ``workers`` local processes (``concurrent.futures.ProcessPoolExecutor``, spawn
  start method), one single-worker pool per slot so that a worker that dies is charged to the
  task it was running and only that slot is restarted;
* ``ray``: Ray tasks on a local instance started here (``num_cpus=workers``) or on an existing
  cluster (``ray_address``); the optional ``cluster`` extra of the package.

Each finished task is written at once to ``<store>/<task id>.json`` (atomically), so an
interrupted campaign (Ctrl-C, a killed worker, a lost node) loses only the tasks in flight;
``resume=True`` loads what is there and computes only what is missing. A task that fails is
retried ``retries`` times (default once), then recorded as failed, without stopping the others;
with ``retry="transient"`` (``azimut eval``) only a failure that can be transient is retried (a
worker that died, a Ray error, ``MemoryError``, ``OSError``: :func:`is_transient`), not an
exception the task's own code raised, which its key would raise again. Each task limits its own
threads (numba, torch, OpenMP/MKL/OpenBLAS) so that ``workers`` processes on as many cores do not
oversubscribe them.

Tasks that name a ``batch`` function (:class:`~jobs.campaign.task.Task`) and share its ``group``
run together, as one call per worker (``azimut eval``: a controller's episodes as one vector env);
each still gets its own record. When a batch raises, each of its tasks is run again alone (with
the same attempt number: an isolation, not a retry), so that one bad episode does not sink the others.

A task is a :class:`~jobs.campaign.task.Task`; its records, checked when read back (a record that
is not valid is recomputed), are :class:`~jobs.campaign.store.TaskStore`'s. Statistics over seeds
(:func:`bootstrap_ci`, :func:`summarize`) are in :mod:`jobs.campaign.statistics`. All are
importable from here; the command-line flags (``--seeds``, ``--workers``, ``--executor``,
``--ray-address``) are in :mod:`jobs.campaign.args`.
"""

from __future__ import annotations

import concurrent.futures as cf
import importlib
import importlib.util
import multiprocessing
import os
import socket
import sys
import time
import traceback
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from jobs.campaign.statistics import bootstrap_ci, summarize  # re-exported
from jobs.campaign.store import TaskStore  # re-exported
from jobs.campaign.task import Task, resolve  # re-exported

__all__ = ["Task", "TaskStore", "EXECUTORS", "run_tasks", "resolve_executor", "ray_available",
           "ClusterUnreachable", "limit_threads", "thread_env", "bootstrap_ci", "summarize", "CampaignInterrupted",
           "RETRY_POLICIES", "TRANSIENT_ERRORS", "is_transient"]

EXECUTORS = ("auto", "serial", "process", "ray")
#: which failures :func:`run_tasks` retries: ``any`` failure, or only the ``transient`` ones
RETRY_POLICIES = ("any", "transient")
#: exceptions raised in a task that can go away on another try (memory, files, the network)
TRANSIENT_ERRORS = (MemoryError, OSError)
#: environment variables read by the thread pools of numba, torch (OpenMP) and BLAS at import
THREAD_ENV_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS")


class CampaignInterrupted(KeyboardInterrupt):
    """Raised by :func:`run_tasks` on Ctrl-C after the finished tasks were saved."""

    def __init__(self, done: int, total: int):
        super().__init__(f"interrupted: {done} of {total} tasks saved; run again with resume to finish")
        self.done, self.total = done, total


# --------------------------------------------------------------------------- thread limits


def thread_env(threads: int) -> dict[str, str]:
    """The environment that caps numba, torch/OpenMP, MKL and OpenBLAS at ``threads`` threads."""
    return {name: str(int(threads)) for name in THREAD_ENV_VARS}


def limit_threads(threads: int | None) -> None:
    """Cap this process's thread pools at ``threads`` (``None``: leave them).

    Sets the environment for libraries not yet imported, and calls ``numba.set_num_threads`` and
    ``torch.set_num_threads`` for those already imported. Meant for worker processes.
    """
    if threads is None:
        return
    threads = max(1, int(threads))
    for name, value in thread_env(threads).items():
        if name == "NUMBA_NUM_THREADS" and "numba" in sys.modules:
            continue  # numba reads it once at import; set_num_threads below caps it instead
        os.environ[name] = value
    if "numba" in sys.modules:
        import numba

        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    if "torch" in sys.modules:
        torch = sys.modules["torch"]
        if torch.get_num_threads() != threads:
            torch.set_num_threads(threads)


def _execute(fn: str, key: Mapping[str, Any], extra: Mapping[str, Any], threads: int | None) -> dict:
    """Run one task in the current process; an exception becomes a failed record."""
    limit_threads(threads)
    start, cpu = time.perf_counter(), time.process_time()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    try:
        result = resolve(fn)(**dict(key), **dict(extra))
        if not isinstance(result, dict):
            raise TypeError(f"task function {fn} returned {type(result).__name__}, expected dict")
        rec = {"status": "ok", "result": result}
    except (Exception, SystemExit) as exc:  # noqa: BLE001 - a task's failure is data, not a crash of the campaign
        # (SystemExit too: a controller's sys.exit() fails its episode, it does not end the campaign)
        rec = _failure(exc)
    rec.update(elapsed_s=time.perf_counter() - start, cpu_s=time.process_time() - cpu, worker=worker)
    return rec


def _execute_unit(fn: str, batch: str, keys: list, extras: list, threads: int | None) -> list[dict]:
    """Run a unit of tasks (:func:`_units`) in the current process: one task through ``fn``, or
    several through their ``batch`` function in one call (each record then carries the batch's
    wall and CPU time and its size, ``batch``). A batch that raises fails all its tasks (the
    executors retry them one by one)."""
    if len(keys) == 1 or not batch:
        return [_execute(fn, key, extra, threads) for key, extra in zip(keys, extras)]
    limit_threads(threads)
    start, cpu = time.perf_counter(), time.process_time()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    try:
        results = resolve(batch)([dict(k) for k in keys], [dict(e) for e in extras])
        if not isinstance(results, list) or len(results) != len(keys) or not all(isinstance(r, dict)
                                                                                  for r in results):
            raise TypeError(f"batch function {batch} must return a list of {len(keys)} dicts")
        recs = [{"status": "ok", "result": r} for r in results]
    except (Exception, SystemExit) as exc:  # noqa: BLE001 - as _execute: data, run again task by task
        recs = [dict(_failure(exc), isolate=True) for _ in keys]
    for rec in recs:
        rec.update(elapsed_s=time.perf_counter() - start, cpu_s=time.process_time() - cpu, worker=worker,
                   batch=len(keys))
    return recs


def _failure(exc: BaseException) -> dict:
    """The failed record of an exception raised by a task's code (in the current ``except``)."""
    return {"status": "failed", "error": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc(),
            "transient": isinstance(exc, TRANSIENT_ERRORS)}


def _lost(exc: BaseException) -> dict:
    """The failed record of a task whose worker died or whose Ray call failed (transient)."""
    first = str(exc).splitlines()[0] if str(exc) else ""
    return {"status": "failed", "error": f"worker lost: {type(exc).__name__}: {first}", "transient": True}


def is_transient(rec: dict) -> bool:
    """Whether a failed record's failure can go away on another try: the worker died, Ray failed,
    or the task raised one of :data:`TRANSIENT_ERRORS` (a record without the flag, from an older
    campaign, counts as transient)."""
    return bool(rec.get("transient", True))


def _again(unit: list[Task], rec: dict, attempt: int, retries: int, retry: str) -> int | None:
    """The attempt number to run a failed task of ``unit`` again with, or None: a failed batch's
    tasks run again alone with the same number (isolation); a task alone is retried while
    ``attempt <= retries``, with ``retry="transient"`` only for a transient failure."""
    if len(unit) > 1 and rec.pop("isolate", False):
        return attempt
    rec.pop("isolate", None)
    if attempt <= retries and (retry == "any" or is_transient(rec)):
        return attempt + 1
    return None


def _units(todo: Sequence[Task], workers: int | None) -> list[list[Task]]:
    """The tasks to run, grouped: tasks with the same ``batch`` function and ``group`` form one
    unit (split into ``workers`` units of near-equal size, so that parallel executors still have
    one per worker; ``workers`` None: no batches), the others one each; longest units first."""
    groups: dict[tuple[str, str, str], list[Task]] = {}
    units: list[list[Task]] = []
    for task in todo:
        if task.batch and workers is not None:
            groups.setdefault((task.fn, task.batch, task.group), []).append(task)
        else:
            units.append([task])
    for members in groups.values():
        parts = min(max(1, workers), len(members))
        units += [members[k::parts] for k in range(parts)]
    return sorted(units, key=lambda u: -sum(t.cost for t in u))


def _unit_args(unit: list[Task]) -> tuple:
    return unit[0].fn, unit[0].batch, [dict(t.key) for t in unit], [dict(t.extra) for t in unit]


#: how often a worker process checks that the campaign's driver is still alive [s]
PARENT_POLL_S = 0.5


def _exit_with_parent(parent: int) -> None:
    """Watchdog of a worker process (a daemon thread): exit at once when the driver ``parent`` is
    gone (the worker is re-parented). Without it a worker outlived a SIGKILLed ``azimut eval
    --workers 2``, and with it the resource tracker, holding the caller's pipes, indefinitely."""
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


def _worker_init(threads: int | None, parent: int | None = None) -> None:
    limit_threads(threads)
    if parent is not None:
        import threading

        threading.Thread(target=_exit_with_parent, args=(parent,), name="azimut-parent-watchdog",
                         daemon=True).start()


# ------------------------------------------------------------------------------- executors


class ClusterUnreachable(ConnectionError):
    """``ray.init`` could not join the cluster at ``--ray-address`` (the command line reports it in
    one line with status 2)."""


def ray_available() -> bool:
    """True when Ray (the ``cluster`` extra) can be imported."""
    try:
        return importlib.util.find_spec("ray") is not None
    except (ImportError, ValueError):
        return False


def resolve_executor(executor: str, workers: int, ray_address: str | None) -> str:
    """``auto``: ``ray`` with an address (a cluster); else ``serial`` for one worker; else local
    processes (on one machine they are lighter than a local Ray instance: ``azimut
    bench-campaign`` compares them; ``docs/results/campaigns.md``). ``ray`` on one machine starts a
    local instance. Raises ``ValueError`` for impossible choices."""
    if executor not in EXECUTORS:
        raise ValueError(f"executor must be one of {', '.join(EXECUTORS)}, got {executor!r}")
    if ray_address and executor not in ("auto", "ray"):
        raise ValueError(f"--ray-address needs the ray executor, not {executor!r}")
    if executor == "auto":
        if ray_address:
            executor = "ray"
        elif workers <= 1:
            executor = "serial"
        else:
            executor = "process"
    if executor == "ray" and not ray_available():
        raise ValueError("the ray executor needs Ray: pip install 'azimut[cluster]'")
    return executor


def _finish(task: Task, rec: dict, attempts: int) -> dict:
    out = {"id": task.id, "fn": task.fn, "key": dict(task.key), "status": rec["status"], "attempts": attempts}
    out.update({k: v for k, v in rec.items() if k != "status"})
    return out


def _settle(unit: list[Task], recs, attempt: int, retries: int, retry, pending: deque):
    """A unit's records: each task to try again goes back to the front of ``pending`` (alone, with
    its next attempt); the others are yielded as (task, record, attempt)."""
    for task, rec in zip(unit, recs):
        again = _again(unit, rec, attempt, retries, retry) if rec["status"] != "ok" else None
        if again is not None:
            pending.appendleft(([task], again))
        else:
            yield task, rec, attempt


def _serial(units, threads, retries, retry):
    pending = deque((unit, 1) for unit in units)
    while pending:
        unit, attempt = pending.popleft()
        yield from _settle(unit, _execute_unit(*_unit_args(unit), threads), attempt, retries, retry, pending)


def _process(units, workers, threads, retries, retry):
    ctx = multiprocessing.get_context("spawn")

    def new_slot():
        return cf.ProcessPoolExecutor(max_workers=1, mp_context=ctx, initializer=_worker_init,
                                      initargs=(threads, os.getpid()))

    slots = [None] * workers
    pending = deque((unit, 1) for unit in units)
    running: dict[cf.Future, tuple[int, list[Task], int]] = {}
    try:
        while pending or running:
            for i in range(workers):
                if not pending:
                    break
                if any(s == i for s, _, _ in running.values()):
                    continue
                if slots[i] is None:
                    slots[i] = new_slot()
                unit, attempt = pending.popleft()
                fut = slots[i].submit(_execute_unit, *_unit_args(unit), threads)
                running[fut] = (i, unit, attempt)
            done, _ = cf.wait(list(running), return_when=cf.FIRST_COMPLETED)
            for fut in done:
                i, unit, attempt = running.pop(fut)
                try:
                    recs = fut.result()
                except Exception as exc:  # noqa: BLE001 - the worker died (BrokenProcessPool) or could not pickle
                    recs = [dict(_lost(exc), isolate=True) for _ in unit]
                    slots[i].shutdown(wait=False, cancel_futures=True)
                    slots[i] = None
                yield from _settle(unit, recs, attempt, retries, retry, pending)
    finally:
        for ex in slots:
            if ex is not None:
                procs = list(getattr(ex, "_processes", {}).values())
                ex.shutdown(wait=False, cancel_futures=True)
                for p in procs:  # a task still running after an interruption: stop its process
                    if p.is_alive():
                        p.terminate()


def _local_import_path() -> str:
    """This driver's import path as PYTHONPATH, so that local Ray workers import the same code."""
    parts = [os.path.abspath(p or os.getcwd()) for p in sys.path]
    seen, out = set(), []
    for p in parts:
        if p not in seen and os.path.isdir(p):
            seen.add(p)
            out.append(p)
    return os.pathsep.join(out)


def _ray(units, workers, threads, retries, ray_address, retry):
    import logging

    import ray

    started = False
    if not ray.is_initialized():
        kwargs = dict(include_dashboard=False, log_to_driver=False, logging_level=logging.WARNING)
        if ray_address:
            try:
                ray.init(address=ray_address, **kwargs)
            except (ConnectionError, RuntimeError) as exc:  # a port that answers but is no Ray head
                raise ClusterUnreachable(f"--ray-address {ray_address}: no Ray cluster answered there "
                                         f"({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})"
                                         ) from exc
        else:
            ray.init(num_cpus=workers, **kwargs)
        started = True
    env = thread_env(threads) if threads else {}
    if not ray_address:
        env["PYTHONPATH"] = _local_import_path()
    remote = ray.remote(_execute_unit).options(num_cpus=1, max_retries=0, runtime_env={"env_vars": env})
    limit = workers if not ray_address or workers > 1 else max(1, int(ray.cluster_resources().get("CPU", 1)))
    pending = deque((unit, 1) for unit in units)
    running: dict[Any, tuple[list[Task], int]] = {}
    try:
        while pending or running:
            while pending and len(running) < limit:
                unit, attempt = pending.popleft()
                running[remote.remote(*_unit_args(unit), threads)] = (unit, attempt)
            done, _ = ray.wait(list(running), num_returns=1)
            for ref in done:
                unit, attempt = running.pop(ref)
                try:
                    recs = ray.get(ref)
                except ray.exceptions.RayError as exc:  # worker crashed, node lost, object lost
                    recs = [dict(_lost(exc), isolate=True) for _ in unit]
                yield from _settle(unit, recs, attempt, retries, retry, pending)
    finally:
        for ref in running:
            ray.cancel(ref, force=True)
        if started:
            ray.shutdown()


def run_tasks(tasks: Sequence[Task], store: TaskStore | str | os.PathLike, *, executor: str = "serial",
              workers: int = 1, threads: int | None = None, ray_address: str | None = None, retries: int = 1,
              resume: bool = False, retry: str = "any", on_result: Callable[[Task, dict], None] | None = None,
              progress: Callable[[int, int, Task, dict], None] | None = None) -> list[dict]:
    """Run ``tasks`` and return their records in the order given.

    Args:
        store: a :class:`TaskStore` or its folder. Without ``resume`` its records are removed first.
        executor: one of :data:`EXECUTORS` (``auto``: see :func:`resolve_executor`).
        workers: parallel tasks (local processes, or the CPUs of a local Ray instance; with
            ``ray_address`` the number in flight, default the cluster's CPUs).
        threads: threads per task (numba, torch, BLAS); default ``cpu_count // workers`` for the
            parallel executors and unchanged for ``serial``.
        retries: how many times a failed task (exception or dead worker) is run again.
        retry: which failures are retried (:data:`RETRY_POLICIES`): ``any``, or only the
            ``transient`` ones (:func:`is_transient`; an exception of the task's own code is
            recorded at once).
        resume: keep the saved records and run only the tasks that have none (or a failed or an
            invalid one, :meth:`TaskStore.load`; the invalid ones are in ``store.rejected``).
        on_result: ``on_result(task, record)`` in this process for each newly finished task before
            it is saved (``record["result"]["artifacts"]`` is there, and dropped afterwards).
        progress: ``progress(done, total, task, record)`` after each newly finished task.

    Raises:
        CampaignInterrupted: on Ctrl-C, after saving what had finished.
        ValueError: before any task runs, if a record could not be written (:meth:`TaskStore.check_writable`).
    """
    if not isinstance(store, TaskStore):
        store = TaskStore(store)
    ids = [t.id for t in tasks]
    if len(set(ids)) != len(ids):
        raise ValueError("two tasks have the same function and key")
    store.check_writable(tasks)
    if retry not in RETRY_POLICIES:
        raise ValueError(f"retry must be one of {', '.join(RETRY_POLICIES)}, got {retry!r}")
    workers = max(1, int(workers))
    executor = resolve_executor(executor, workers, ray_address)
    if threads is None and executor != "serial":
        threads = max(1, (os.cpu_count() or 1) // workers)
    if not resume:
        store.clear()
    records: dict[str, dict] = {}
    for task in tasks:
        rec = store.load(task) if resume else None
        if rec is not None and rec.get("status") == "ok":
            records[task.id] = rec
    todo = sorted((t for t in tasks if t.id not in records), key=lambda t: -t.cost)  # longest first
    # batchable tasks together, in as many units as workers (a cluster of unknown size: none)
    units = _units(todo, 1 if executor == "serial" else None if executor == "ray" and ray_address and workers <= 1
                   else workers)
    total, done = len(tasks), len(records)
    if executor == "serial":
        stream = _serial(units, threads, retries, retry)
    elif executor == "process":
        stream = _process(units, workers, threads, retries, retry)
    else:
        stream = _ray(units, workers, threads, retries, ray_address, retry)
    try:
        for task, rec, attempts in stream:
            rec = _finish(task, rec, attempts)
            if on_result is not None:
                on_result(task, rec)
            if isinstance(rec.get("result"), dict):
                rec["result"].pop("artifacts", None)
            store.save(task, rec)
            records[task.id] = rec
            done += 1
            if progress is not None:
                progress(done, total, task, rec)
    except KeyboardInterrupt:
        stream.close()
        raise CampaignInterrupted(done, total) from None
    return [records[i] for i in ids]
