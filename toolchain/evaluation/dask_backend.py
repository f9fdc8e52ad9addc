"""The Dask backend of `executor.execute`: joblib `delayed` tasks on an existing cluster, and nothing lost with a
worker, in any phase (the source models' training, the MCCV jobs).

The arguments the tasks share (everything but plain numbers and strings: the dataset, the sources, the target
rows, the settings) are scattered to every worker once (`broadcast`) and the tasks refer to them. A worker that
dies (SIGKILL, a reboot, a pre-empted Slurm job) can take two things with it:

- the task it was running: the scheduler runs it again on another worker by itself (up to its
  `allowed-failures`, then the task fails with KilledWorker);
- scattered data. A broadcast does not keep a copy on every worker: the scheduler's Active Memory Manager (on by
  default, every 2 s) drops the copies that no queued task needs, so while a phase's last task runs (the expert
  training is a phase of one task) its worker holds the only copy of the task's inputs. Scattered data cannot be
  recomputed: when that worker dies the scheduler forgets it and cancels every task that needs it
  ("cancelled for reason: already forgotten").

A task cancelled that way, or whose result was lost before it was read, is submitted again (at most
TASK_RESUBMITS times), once its inputs have been scattered again wherever the scheduler no longer holds them.
Every job seeds itself from its own arguments, so a resubmitted task returns what the first would have. While
the cluster has no worker at all the evaluation waits for one, up to `no_workers_timeout()`; what cannot be
recovered (no worker for that long, a task that every worker running it died under) ends with one line
(FleetlabError), not a traceback.
"""

from __future__ import annotations

import sys
import time
from concurrent.futures import CancelledError
from typing import Callable

from ..errors import FleetlabError, InputError, first_line

TASK_RESUBMITS = 3  # a task whose inputs or result were lost with a worker is submitted again this often
NO_WORKERS_TIMEOUT_S = 300.0  # how long a cluster left without workers is waited for (see no_workers_timeout)
SCATTER_ATTEMPTS = 3  # a scatter that fails (a worker died while data was sent to it) is tried again this often
_POLL_S = 0.05  # how often finished tasks are looked for
_CHECK_S = 1.0  # how often the scheduler is asked whether it still has workers while tasks run


def no_workers_timeout() -> float:
    """Seconds to wait while the cluster has no worker before giving up: Dask's own setting for that,
    `distributed.scheduler.no-workers-timeout` (e.g. DASK_DISTRIBUTED__SCHEDULER__NO_WORKERS_TIMEOUT=10min in
    fleetlab's environment), where it is set, else NO_WORKERS_TIMEOUT_S."""
    import dask
    from dask.utils import parse_timedelta

    value = dask.config.get("distributed.scheduler.no-workers-timeout", None)
    return NO_WORKERS_TIMEOUT_S if value is None else float(parse_timedelta(value, default="s"))


def _plain(a) -> bool:
    """An argument sent inside its task (a number, a string); anything else is scattered once."""
    return isinstance(a, (int, float, str, type(None)))


def _label(task) -> str:
    """A task in a message: its function and its plain arguments, e.g. run_job(150, 3, 'acomerge')."""
    fn, args, _ = task
    return f"{getattr(fn, '__name__', 'task')}({', '.join(repr(a) for a in args if _plain(a))})"


class _Lost(Exception):
    """A task's future was cancelled, or its result lost, with a worker: submit it again."""


def run_on_dask(tasks: list, scheduler: str, ordered: bool, finished: Callable) -> list:
    """Run joblib `delayed` tasks on the Dask cluster at `scheduler`; `finished(result)` is called as each one
    finishes. Returns the results in task order with `ordered`, else in completion order."""
    from dask.distributed import Client

    with Client(scheduler, timeout="30s") as client:
        nthreads = client.nthreads()
        if not nthreads:
            raise InputError(f"the Dask scheduler at {scheduler} has no workers; start some with "
                             f"'dask worker {scheduler} --nthreads 1'")
        if any(n > 1 for n in nthreads.values()):
            # torch seeds dropout through its per-process global RNG: two jobs in threads of one
            # worker would interleave their draws and the numbers would depend on timing.
            print("warning: Dask workers with more than one thread; start them with --nthreads 1 "
                  "for results identical to the local backend", file=sys.stderr)
        try:
            return _Run(client, scheduler, tasks).run(ordered, finished)
        except OSError as e:
            if client.status == "running":  # not the cluster's (a result file that could not be written)
                raise
            raise FleetlabError(f"lost the Dask scheduler at {scheduler}: {first_line(e)}") from None


class _Run:
    def __init__(self, client, scheduler: str, tasks: list):
        self.client, self.scheduler, self.tasks = client, scheduler, tasks
        self.timeout = no_workers_timeout()
        self.submits = [0] * len(tasks)
        # The shared arguments: the same objects in every task, scattered once (and again when lost).
        self.objects: dict[int, object] = {}
        for _, args, kw in tasks:
            for a in (*args, *kw.values()):
                if not _plain(a):
                    self.objects.setdefault(id(a), a)
        self.shared: dict[int, object] = {}  # id of a shared object -> its scattered future

    # ------------------------------------------------------------------------------------------ shared data
    def _scatter(self, ids: list[int]) -> None:
        for attempt in range(SCATTER_ATTEMPTS):
            self._wait_for_a_worker()
            try:
                for i in ids:
                    # a one-element list: scatter would split a list or dict argument into its items
                    self.shared[i] = self.client.scatter([self.objects[i]], broadcast=True, hash=False)[0]
                return
            except OSError as e:  # a worker died while the data went to it (CommClosedError, a timeout)
                if attempt == SCATTER_ATTEMPTS - 1:
                    raise FleetlabError(f"could not send the jobs' data to the Dask workers of {self.scheduler} "
                                        f"({SCATTER_ATTEMPTS} tries, workers lost meanwhile?): {first_line(e)}") from None
                ids = self._lost_shared()

    def _lost_shared(self) -> list[int]:
        """The shared objects the cluster no longer holds (not yet scattered, or every copy lost)."""
        futures = {i: f for i, f in self.shared.items() if f.status == "finished"}
        held = self.client.who_has(list(futures.values())) if futures else {}
        return [i for i in self.objects if i not in futures or not held.get(futures[i].key)]

    def _args(self, values):
        return [a if _plain(a) else self.shared[id(a)] for a in values]

    # -------------------------------------------------------------------------------------------- workers
    def _wait_for_a_worker(self) -> None:
        if self.client.nthreads():
            return
        end = time.monotonic() + self.timeout
        while not self.client.nthreads():
            if time.monotonic() > end:
                raise FleetlabError(self._no_workers())
            time.sleep(0.2)

    def _no_workers(self) -> str:
        return (f"the Dask scheduler at {self.scheduler} has had no worker for {self.timeout:g} s (all lost); "
                f"start workers ('dask worker {self.scheduler} --nthreads 1') and run the evaluation again "
                f"(--resume keeps the runs already written)")

    # ------------------------------------------------------------------------------------------------ run
    def _submit(self, i: int):
        self.submits[i] += 1
        fn, args, kw = self.tasks[i]
        keywords = dict(zip(kw, self._args(kw.values())))
        return self.client.submit(fn, *self._args(args), pure=False, **keywords)

    def _outcome(self, future, i: int):
        """The task's result; _Lost when it must run again; FleetlabError when it cannot."""
        from distributed.scheduler import KilledWorker, NoValidWorkerError

        if future.status == "cancelled":  # its inputs were lost with a worker (or someone cancelled it)
            raise _Lost
        if future.status == "error":
            error = future.exception()
            if isinstance(error, KilledWorker):
                raise FleetlabError(f"every Dask worker that ran {_label(self.tasks[i])} died while running it "
                                    f"(out of memory? see the workers' logs)") from None
            if isinstance(error, NoValidWorkerError):
                raise FleetlabError(self._no_workers()) from None
        try:
            return future.result()  # the job's own error is raised here, with its traceback
        except CancelledError:  # finished, but its result was lost with its worker and could not be made again
            raise _Lost from None

    def run(self, ordered: bool, finished: Callable) -> list:
        from dask.distributed import as_completed

        self._scatter(list(self.objects))
        pending = {self._submit(i): i for i in range(len(self.tasks))}
        queue = as_completed(list(pending))
        results: dict[int, object] = {}
        workerless_since, checked = None, time.monotonic()
        while pending:
            batch = queue.next_batch(block=False)
            if not batch:
                time.sleep(_POLL_S)
                if time.monotonic() - checked >= _CHECK_S:
                    # tasks wait for a worker without end on a cluster that has none: give up after the timeout
                    checked = time.monotonic()
                    if self.client.nthreads():
                        workerless_since = None
                    elif workerless_since is None:
                        workerless_since = checked
                    elif checked - workerless_since > self.timeout:
                        raise FleetlabError(self._no_workers())
                continue
            lost = []
            for future in batch:
                i = pending.pop(future)
                try:
                    results[i] = self._outcome(future, i)
                except _Lost:
                    lost.append(i)
                    continue
                finished(results[i])
            if lost:
                again = [i for i in lost if self.submits[i] > TASK_RESUBMITS]
                if again:
                    raise FleetlabError(f"{_label(self.tasks[again[0]])} was lost with a Dask worker "
                                        f"{self.submits[again[0]]} times; is the cluster losing its workers?")
                self._scatter(self._lost_shared())
                for i in lost:
                    future = self._submit(i)
                    pending[future] = i
                    queue.add(future)
        return [results[i] for i in range(len(self.tasks))] if ordered else list(results.values())
