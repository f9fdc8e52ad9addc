"""`fleetlab evaluate` on a real Dask cluster and after an interruption.

A real `dask scheduler` and two `dask worker --nthreads 1 --no-nanny` processes listen on
127.0.0.1 over TCP. The evaluation on them gives the local run's scores; a worker killed with
SIGKILL while jobs run loses nothing (its jobs run again on the other worker); an evaluation
killed half-way and continued with `--resume` ends with the uninterrupted run's table. The
budgets are small (a few seconds per evaluation) so the file fits CI's two cores.
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
from fleetlab.evaluation.mccv import RUNS_DIR, EvalSettings, job_file, run_mccv, write_atomic
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


@pytest.fixture()
def cluster(tmp_path):
    """A scheduler and two single-threaded workers (no nanny: a killed worker stays dead)."""
    file = tmp_path / "scheduler.json"
    env = {**os.environ, "DASK_DISTRIBUTED__WORKER__DAEMON": "False"}
    procs = [subprocess.Popen([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--no-dashboard", "--scheduler-file", str(file)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)]
    try:
        address = _wait_for(lambda: file.is_file() and json.loads(file.read_text() or "{}").get("address"),
                            60, "the scheduler's address")
        assert address.startswith("tcp://127.0.0.1:")
        for _ in range(2):
            procs.append(subprocess.Popen([str(BIN / "dask"), "worker", address, "--nthreads", "1", "--no-nanny",
                                           "--no-dashboard", "--host", "127.0.0.1"],
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env))
        from dask.distributed import Client

        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
            pids = client.run(os.getpid)  # worker address -> its process id
        assert sorted(pids.values()) == sorted(p.pid for p in procs[1:])
        yield address, procs[1:]
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        for p in procs:
            try:
                p.wait(timeout=5)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


def _evaluate(data: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([str(BIN / "fleetlab"), "evaluate", "--data", str(data), *CLI_ARGS, *extra],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def test_dask_cluster_equals_local_run(data, local, cluster, tmp_path):
    address, _ = cluster
    out = tmp_path / "dask"
    proc = _evaluate(data, "--backend", "dask", "--scheduler", address, "--out", str(out))
    assert proc.wait(timeout=300) == 0, proc.stderr.read()
    result = json.loads((out / "results.json").read_text())
    assert result["timing"]["backend"] == "dask"
    assert scores(result) == scores(local)


def test_killed_worker_loses_nothing(data, local, cluster, tmp_path):
    address, workers = cluster
    out = tmp_path / "killed"
    proc = _evaluate(data, "--backend", "dask", "--scheduler", address, "--out", str(out))
    _wait_for(lambda: _done_jobs(out) >= 1, 240, "the first finished job", proc)
    workers[0].send_signal(signal.SIGKILL)  # jobs are still queued on both workers: one is lost mid-run
    workers[0].wait(timeout=20)
    assert _done_jobs(out) < N_JOBS  # the worker really died while the evaluation was running
    assert proc.wait(timeout=300) == 0, proc.stderr.read()
    result = json.loads((out / "results.json").read_text())
    assert scores(result) == scores(local)
    assert workers[1].poll() is None  # the other worker did the rest


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
