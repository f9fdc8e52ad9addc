"""`fleetlab evaluate` on a real Dask cluster and after an interruption.

A real `dask scheduler` and two `dask worker --nthreads 1 --no-nanny` processes listen on
127.0.0.1 over TCP. The evaluation on them gives the local run's scores. A worker killed with
SIGKILL loses nothing in any phase that runs on the cluster (the experts' training, the MCCV jobs):
the moment of each kill is chosen by what the scheduler reports (a task of that phase processing on
the worker, and for the worst case the only copy of its scattered inputs there too), and the
evaluation still ends with the local run's scores; a cluster left without any worker ends the
evaluation with one line. An evaluation killed half-way and continued with `--resume` ends with the
uninterrupted run's table. The budgets are small (a few seconds per evaluation) so the file fits
CI's two cores.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fleetlab.cli import main
from fleetlab.data.dataset import load_dataset
from fleetlab.evaluation.executor import RUNS_DIR, job_file, write_atomic
from fleetlab.evaluation.mccv import run_mccv
from fleetlab.evaluation.protocol import EvalSettings
from fleetlab.fusion.registry import Budget

SETTINGS = EvalSettings(protocol="paper", cal_sizes=(150,), runs=6, seed=3, epochs=1,
                        budget=Budget(steps=60, ants=150), methods=("earth-ft", "acomerge"))
CLI_ARGS = ["--cal-size", "150", "--runs", "6", "--seed", "3", "--epochs", "1", "--generations", "60",
            "--ants", "150", "--methods", "earth-ft,acomerge", "--no-progress"]
N_JOBS = 6 * 2
BIN = Path(sys.executable).parent


def scores(result: dict) -> dict:
    """Every method's per-run scores and the t-tests: what must not depend on how the jobs ran."""
    return {"results": result["results"], "ttest": result["ttest"], "convergence": result["convergence"]}


@pytest.fixture(scope="module")
def data(real_data_dir):
    return real_data_dir


@pytest.fixture(scope="module")
def local(data):
    return run_mccv(load_dataset(data), SETTINGS, n_jobs=1, progress=False)


def _wait_for(predicate, timeout: float, what: str, proc: subprocess.Popen | None = None):
    end = time.monotonic() + timeout
    while time.monotonic() < end:  # safety net: the wait ends on the predicate, then fails naming `what`
        value = predicate()
        if value:
            return value
        if proc is not None and proc.poll() is not None:
            raise AssertionError(f"process ended ({proc.returncode}) before {what}: {proc.stderr.read()}")
        time.sleep(0.02)
    raise AssertionError(f"timed out waiting for {what}")


def _done_jobs(folder: Path) -> int:
    return len([p for p in (folder / RUNS_DIR).glob("*.json") if p.name != "settings.json"])


# What the scheduler and the workers run with. The Active Memory Manager (on by default) drops the copies of
# scattered data that no queued job needs, every 2 s by default: here every 0.1 s, so that the worst moment for
# a kill (the only copy of a job's inputs on the worker that dies) comes at once instead of by chance.
CLUSTER_ENV = {"DASK_DISTRIBUTED__WORKER__DAEMON": "False",
               "DASK_DISTRIBUTED__SCHEDULER__ACTIVE_MEMORY_MANAGER__INTERVAL": "100ms"}
JOB_PREFIXES = ("_train_experts_job", "_train_joint_job", "run_job")  # the tasks' keys; the rest is scattered data


class Cluster:
    """A scheduler and single-threaded workers on 127.0.0.1 (no nanny: a killed worker stays dead)."""

    def __init__(self, tmp_path: Path):
        self.env = {**os.environ, **CLUSTER_ENV}
        self.procs: list[subprocess.Popen] = []
        self.pids: dict[str, int] = {}  # worker address -> its process id
        file = tmp_path / "scheduler.json"
        self.procs.append(subprocess.Popen([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0",
                                            "--no-dashboard", "--scheduler-file", str(file)],
                                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=self.env))
        self.address = _wait_for(lambda: file.is_file() and json.loads(file.read_text() or "{}").get("address"),
                                 60, "the scheduler's address")
        assert self.address.startswith("tcp://127.0.0.1:")

    @property
    def workers(self) -> list[subprocess.Popen]:
        return self.procs[1:]

    def start_workers(self, n: int, client) -> None:
        """Start `n` more workers and wait until the scheduler has them all."""
        for _ in range(n):
            self.procs.append(subprocess.Popen([str(BIN / "dask"), "worker", self.address, "--nthreads", "1",
                                                "--no-nanny", "--no-dashboard", "--host", "127.0.0.1"],
                                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=self.env))
        alive = sorted(p.pid for p in self.workers if p.poll() is None)

        def joined():  # the scheduler's workers are these processes: the new ones in, a killed one out
            pids = client.run(os.getpid, on_error="ignore")  # worker address -> its process id
            return pids if sorted(pids.values()) == alive else None

        self.pids = _wait_for(joined, 60, f"the scheduler's workers to be the processes {alive}")

    def kill_worker_running(self, client, prefix: str, proc: subprocess.Popen, sole_copy: bool = False) -> str:
        """SIGKILL the worker on which the scheduler reports a task of `prefix` processing; with `sole_copy`,
        once the scheduler also holds every scattered input on that worker only (lost with it). Returns the
        key of the task it was running."""
        procs = {address: next(p for p in self.workers if p.pid == pid) for address, pid in self.pids.items()}

        def running():
            for worker, keys in client.processing().items():
                key = next((k for k in keys if str(k).startswith(prefix)), None)
                if key is None or worker not in procs or procs[worker].poll() is not None:  # not one killed before
                    continue
                inputs = {k: w for k, w in client.who_has().items() if not str(k).startswith(JOB_PREFIXES)}
                if not sole_copy or (inputs and all(list(w) == [worker] for w in inputs.values())):
                    return worker, key

        worker, key = _wait_for(running, 240, f"a {prefix} task processing" + (" on its inputs' only worker"
                                                                            if sole_copy else ""), proc)
        victim = procs[worker]
        victim.send_signal(signal.SIGKILL)
        victim.wait(timeout=20)
        return key

    def close(self) -> None:
        for p in reversed(self.procs):  # nothing to keep: SIGKILL (a worker's SIGTERM takes seconds)
            if p.poll() is None:
                p.kill()
        for p in self.procs:
            p.wait()


@pytest.fixture()
def cluster(tmp_path):
    """A scheduler and two single-threaded workers."""
    from dask.distributed import Client

    c = None
    try:
        c = Cluster(tmp_path)
        with Client(c.address, timeout="30s") as client:
            c.start_workers(2, client)
        yield c
    finally:
        if c is not None:
            c.close()


def _evaluate(data: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([str(BIN / "fleetlab"), "evaluate", "--data", str(data), *CLI_ARGS, *extra],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def test_dask_cluster_equals_local_run(data, local, cluster, tmp_path):
    out = tmp_path / "dask"
    proc = _evaluate(data, "--backend", "dask", "--scheduler", cluster.address, "--out", str(out))
    assert proc.wait(timeout=300) == 0, proc.stderr.read()
    result = json.loads((out / "results.json").read_text())
    assert result["timing"]["backend"] == "dask"
    assert scores(result) == scores(local)


def test_a_worker_killed_in_any_phase_loses_nothing(data, local, cluster, tmp_path):
    """One evaluation, a worker killed with SIGKILL in every phase that runs on the cluster, each at a moment
    the scheduler reports: the evaluation ends with the local run's scores."""
    from dask.distributed import Client

    out = tmp_path / "killed"
    proc = _evaluate(data, "--backend", "dask", "--scheduler", cluster.address, "--out", str(out))
    with Client(cluster.address, timeout="30s") as client:
        # The source models: the experts' training, once the Active Memory Manager has left its inputs (the
        # dataset, the settings) on its own worker only: they die with it.
        cluster.kill_worker_running(client, "_train_experts_job", proc, sole_copy=True)
        assert _done_jobs(out) == 0  # still training
        cluster.start_workers(1, client)
        # The MCCV jobs: a job dies with its worker, the other worker carries on.
        cluster.kill_worker_running(client, "run_job", proc)
        # ... and then the last worker, which holds the only copy of the sources, while it runs a job: for a
        # moment the cluster has no worker at all, until a new one comes.
        cluster.kill_worker_running(client, "run_job", proc, sole_copy=True)
        assert _done_jobs(out) < N_JOBS
        cluster.start_workers(1, client)
    assert proc.wait(timeout=300) == 0, proc.stderr.read()
    result = json.loads((out / "results.json").read_text())
    assert scores(result) == scores(local)
    assert sum(p.poll() is None for p in cluster.workers) == 1  # the last one did the rest


def test_a_cluster_without_workers_ends_with_one_line(data, cluster, tmp_path):
    """Every worker killed while the experts train, none started again: after Dask's no-workers-timeout (set
    in fleetlab's environment) the evaluation ends with one line saying so, not a traceback."""
    from dask.distributed import Client

    env = {**os.environ, "DASK_DISTRIBUTED__SCHEDULER__NO_WORKERS_TIMEOUT": "1s"}
    proc = subprocess.Popen([str(BIN / "fleetlab"), "evaluate", "--data", str(data), *CLI_ARGS, "--backend", "dask",
                             "--scheduler", cluster.address, "--out", str(tmp_path / "out")],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
    with Client(cluster.address, timeout="30s") as client:
        for _ in cluster.workers:
            cluster.kill_worker_running(client, "_train_experts_job", proc)
    assert proc.wait(timeout=120) == 2
    err = proc.stderr.read()
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert err.startswith("fleetlab evaluate: error: the Dask scheduler at tcp://127.0.0.1:") and "no worker" in err


def test_resume_after_a_kill_equals_an_uninterrupted_run(data, local, tmp_path):
    out = tmp_path / "resumed"
    proc = _evaluate(data, "--out", str(out))
    _wait_for(lambda: _done_jobs(out) >= N_JOBS // 2, 240, "half of the jobs", proc)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=20)
    stopped_at = _done_jobs(out)
    assert stopped_at < N_JOBS and not (out / "results.json").exists()
    for path in (out / RUNS_DIR).glob("*.json"):  # whatever the kill hit, every file is whole
        json.loads(path.read_text())
    resumed = _evaluate(data, "--resume", str(out))
    assert resumed.wait(timeout=300) == 0, resumed.stderr.read()
    result = json.loads((out / "results.json").read_text())
    assert result["timing"]["resumed_jobs"] == stopped_at
    assert scores(result) == scores(local)


def test_resume_refuses_other_settings_and_foreign_folders(data, tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert main(["evaluate", "--data", str(data), *CLI_ARGS, "--resume", str(tmp_path / "empty")]) != 0
    assert "settings.json" in capsys.readouterr().err
    write_atomic(job_file(tmp_path / "other", 150, 0, "acomerge").parent / "settings.json", json.dumps({"runs": 99}))
    assert main(["evaluate", "--data", str(data), *CLI_ARGS, "--resume", str(tmp_path / "other")]) != 0
    err = capsys.readouterr().err
    assert "other settings" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
