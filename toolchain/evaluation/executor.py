"""The MCCV job executor: joblib tasks run locally (loky) or on a Dask cluster, and every finished job kept
in the results folder so that an interrupted evaluation resumes where it stopped.

Local processes (loky) or an existing Dask cluster (joblib's dask backend, `dask_backend`): the jobs' results
do not depend on the backend, the number of workers or the order of completion (`protocol`). Dask workers
should run one thread each (`dask worker ADDRESS --nthreads 1`): torch draws dropout masks from a per-process
global RNG, which threads would share.

Every finished job is written at once to RESULTS/runs/<cal>-<run>-<method>.json (atomically: a temporary file
renamed over the name, so a crash leaves either the whole file or none); `load_done` reads them back, and the
evaluation runs only the jobs still missing. The jobs' results are the same whichever run produced them, so a
resumed table equals an uninterrupted one.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from dataclasses import asdict
from pathlib import Path

import joblib
from tqdm.auto import tqdm

from ..errors import InputError
from .protocol import EvalSettings

BACKENDS = ("loky", "dask")
RUNS_DIR = "runs"  # per-job results inside an evaluation's results folder


def execute(
    tasks: list, n_jobs: int, backend: str, scheduler: str | None, progress: bool, ordered: bool = False,
    on_result=None,
) -> list:
    """Run joblib `delayed` tasks locally (loky) or on a Dask cluster; results in completion
    order, or in task order with `ordered`. `on_result(result)` is called as each one finishes.

    On Dask (`dask_backend`), arguments shared by the tasks (the sources, the target rows) are scattered
    once to every worker; a task lost with a worker, or whose inputs were, runs again on another."""
    if backend not in BACKENDS:
        raise InputError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
    if not tasks:
        return []
    bar = tqdm(total=len(tasks), desc="MCCV jobs", disable=not progress)
    done = []

    def finished(result):
        done.append(result)
        bar.update(1)
        if on_result is not None:
            on_result(result)

    try:
        if backend == "loky":
            runner = joblib.Parallel(n_jobs=min(n_jobs, len(tasks)), backend="loky",
                                     return_as="generator" if ordered else "generator_unordered")
            for result in runner(tasks):
                finished(result)
            return done
        if not scheduler:
            raise InputError("--backend dask needs --scheduler ADDRESS of a running Dask scheduler")
        from .dask_backend import run_on_dask

        return run_on_dask(tasks, scheduler, ordered, finished)
    finally:
        bar.close()


def job_file(folder: Path, cal_size: int, run: int, method: str) -> Path:
    return Path(folder) / RUNS_DIR / f"{cal_size}-{run}-{method}.json"


def write_atomic(path: Path, text: str) -> None:
    """Write `text` to `path` so that a crash leaves the old file or the whole new one, never a part."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def settings_key(settings: EvalSettings) -> dict:
    """What a saved job depends on (JSON-normalised): a resume must use the same settings."""
    return json.loads(json.dumps(asdict(settings)))


def load_done(folder: Path, settings: EvalSettings) -> dict[tuple[int, int, str], dict]:
    """The jobs already finished in `folder` (written by an earlier, maybe interrupted, evaluation)."""
    folder = Path(folder)
    saved = folder / RUNS_DIR / "settings.json"
    if not saved.is_file():
        raise InputError(f"--resume {folder}: no {RUNS_DIR}/settings.json there (not an evaluation's results folder)")
    if json.loads(saved.read_text()) != settings_key(settings):
        raise InputError(f"--resume {folder}: it was made with other settings ({saved}); use the same options")
    done = {}
    for c in settings.cal_sizes:
        for r in range(settings.runs):
            for m in settings.all_methods:
                path = job_file(folder, c, r, m)
                if path.is_file():
                    done[(c, r, m)] = json.loads(path.read_text())
    return done


def save_settings(folder: Path, settings: EvalSettings) -> None:
    """Record what the jobs in `folder` depend on, for a later resume to compare."""
    write_atomic(Path(folder) / RUNS_DIR / "settings.json", json.dumps(settings_key(settings)))


def save_job(folder: Path, job: dict) -> None:
    """Keep one finished job (a `protocol.run_jobs` result) where `load_done` finds it."""
    write_atomic(job_file(folder, job["cal_size"], job["run"], job["method"]), json.dumps(job))


class Progress:
    """One bar per method (runs done of runs to do, with the time left), for any backend."""

    def __init__(self, todo: dict[str, int], done: dict[str, int], device: str, enabled: bool):
        self.bars = {m: tqdm(total=todo[m] + done.get(m, 0), initial=done.get(m, 0), position=i, leave=True,
                             desc=f"{m} [{device}]", unit="run", disable=not enabled, dynamic_ncols=True)
                     for i, m in enumerate(todo)}

    def finished(self, job: dict) -> None:
        bar = self.bars[job["method"]]
        bar.set_postfix_str(f"|D_Cal|={job['cal_size']} run {job['run']}", refresh=False)
        bar.update(1)

    def close(self) -> None:
        for bar in self.bars.values():
            bar.close()
