"""The MCCV summary: per method and calibration size the mean and spread of every metric over the runs, the
best-vs-second t-test, the convergence curves, and where the evaluation's CPU time went."""

from __future__ import annotations

from dataclasses import asdict

import numpy as np

from .methods import UNRANKED_GROUPS, table_groups
from .metrics import SCALAR_METRICS
from .protocol import EvalSettings
from .stats import FORMS, corrected_resampled_ttest

ALPHA = 0.05  # significance level of the best-vs-second t-test


def _mean_std(values: list) -> dict:
    a = np.asarray(values, dtype=float)
    std = a.std(axis=0, ddof=1) if a.shape[0] > 1 else np.zeros_like(a[0])
    mean = a.mean(axis=0)
    return {"mean": mean.tolist(), "std": std.tolist()}


def summarise(jobs: list[dict], settings: EvalSettings) -> dict:
    """Per method and cal size: mean ± std over runs (sample std, ddof=1) of every metric, the
    per-run scores, summed confusion matrices; t-test of best vs second; convergence curves.

    JSON layout: {"results": {METHOD: {"150": {"balanced_accuracy": {"mean", "std", "runs"},
    "macro_f1": {...}, "precision": {...}, "recall": {...}, "confusion_matrix": ...,
    "calibration_fit": {"balanced_accuracy": {"mean", "std"}, "macro_f1": {...}}, ...}}},
    "ttest": {...}, "convergence": {...}, "config": {...}}.
    """
    results: dict[str, dict] = {}
    convergence: dict[str, dict] = {}
    for m in settings.all_methods:
        results[m], convergence_m = {}, {}
        for c in settings.cal_sizes:
            rs = [j for j in jobs if j["method"] == m and j["cal_size"] == c]
            entry = {k: {**_mean_std([r[k] for r in rs]), "runs": [r[k] for r in rs]} for k in SCALAR_METRICS}
            entry.update({k: _mean_std([r[k] for r in rs]) for k in ("precision", "recall")})
            entry["confusion_matrix"] = np.sum([r["confusion_matrix"] for r in rs], axis=0).tolist()
            entry["calibration_fit"] = {k: _mean_std([r["calibration_fit"][k] for r in rs]) for k in SCALAR_METRICS}
            entry["n_runs"] = len(rs)
            entry["n_cal"] = int(rs[0]["n_cal"])
            if "label_noise" in rs[0]:  # the same corrupted labels for every method of a draw
                corrupted = [r["label_noise"]["corrupted"] for r in rs]
                entry["label_noise"] = {"model": settings.label_noise, "corrupted_mean": float(np.mean(corrupted)),
                                        "corrupted_fraction": float(np.sum(corrupted) / np.sum(
                                            [r["label_noise"]["of"] for r in rs]))}
            entry["n_test_mean"] = float(np.mean([r["n_test"] for r in rs]))
            results[m][str(c)] = entry
            if rs[0]["history"]:  # methods that keep a convergence curve
                convergence_m[str(c)] = _mean_std([r["history"] for r in rs])
        if convergence_m:
            convergence[m] = convergence_m
    return {
        "results": results,
        "ttest": best_vs_second(results, settings),
        "convergence": convergence,
        "config": {**asdict(settings), "methods": list(settings.all_methods), "split_seed": "run index",
                   "std": "sample std over runs (ddof=1)"},
    }


def table_methods(results: dict) -> list[str]:
    """Methods that compete for best/second: the paper's table (not the ablations)."""
    main = [m for g, ms in table_groups().items() if g not in UNRANKED_GROUPS for m in ms]
    return [m for m in main if m in results]


def best_vs_second(results: dict, settings: EvalSettings) -> dict:
    """For every cal size and metric: rank the table's methods by mean, and test best vs second
    with the corrected resampled t-test on their paired per-run scores (see `stats`)."""
    out: dict[str, dict] = {}
    methods = table_methods(results)
    for c in map(str, settings.cal_sizes):
        out[c] = {}
        for metric in SCALAR_METRICS:
            ranked = sorted(methods, key=lambda m: -results[m][c][metric]["mean"])
            entry: dict = {"ranking": ranked}
            if len(ranked) >= 2 and settings.runs >= 2:
                best, second = ranked[:2]
                n_train, n_test = results[best][c]["n_cal"], results[best][c]["n_test_mean"]
                a, b = results[best][c][metric]["runs"], results[second][c][metric]["runs"]
                tests = {form: corrected_resampled_ttest(a, b, n_train, n_test, form).as_dict() for form in FORMS}
                entry.update(best=best, second=second, n_train=n_train, n_test=n_test, alpha=ALPHA,
                             significant=bool(tests["nadeau-bengio"]["p"] < ALPHA), tests=tests)
            out[c][metric] = entry
    return out


def cpu_breakdown(jobs: list[dict], source_seconds: dict[str, float], methods: tuple[str, ...]) -> dict:
    """Where the evaluation's CPU time went: the source models' training (CPU seconds of their jobs)
    and every method's jobs (sum over its runs, and the mean per run), and of the jobs' time the part
    spent in fitness calls. CPU time, not wall time: on a shared machine it is what the work itself
    cost. Jobs read back by --resume from an older fleetlab may lack it (counted as missing)."""
    timed = [j for j in jobs if "cpu_seconds" in j and "fitness_cpu_seconds" in j]
    per_method = {m: float(sum(j["cpu_seconds"] for j in timed if j["method"] == m)) for m in methods}
    in_fitness = {m: float(sum(j["fitness_cpu_seconds"] for j in timed if j["method"] == m)) for m in methods}
    sources = {k[: -len("_cpu")]: v for k, v in source_seconds.items() if k.endswith("_cpu")}
    return {
        "sources_cpu_s": sources,
        "method_cpu_s": per_method,
        "method_mean_cpu_s": {m: per_method[m] / max(1, sum(1 for j in timed if j["method"] == m)) for m in methods},
        "method_fitness_cpu_s": in_fitness,
        "cpu_s": float(sum(sources.values()) + sum(per_method.values())),
        "fitness_cpu_s": float(sum(in_fitness.values())),
        "jobs_without_cpu_time": len(jobs) - len(timed),
    }
