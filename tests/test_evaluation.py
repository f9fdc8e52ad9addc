"""MCCV evaluation: metrics, the JSON layout, determinism across backends (local processes,
Dask), the paper-style table, and `fleetlab evaluate` end to end on the real data with
tiny budgets."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from fleetlab.cli import main
from fleetlab.compute import usable_cores
from fleetlab.data.dataset import load_dataset
from fleetlab.evaluation.mccv import run_mccv
from fleetlab.evaluation.protocol import EvalSettings
from fleetlab.evaluation.methods import default_methods, parse_methods, selectable
from fleetlab.evaluation.metrics import balanced_accuracy, classification_metrics
from fleetlab.evaluation.tables import markdown_table
from fleetlab.fusion.bench import table_figures
from fleetlab.fusion import registry
from fleetlab.fusion.registry import Budget
from required import need_module

TINY = Budget(steps=3, ants=6)


def comparable(result: dict) -> dict:
    """Everything but wall-clock timing, which legitimately differs between runs."""
    return {k: v for k, v in result.items() if k != "timing"}


@pytest.fixture(scope="module")
def dataset(real_data_dir):
    return load_dataset(real_data_dir)


@pytest.fixture(scope="module")
def small_settings():
    return EvalSettings(protocol="paper", cal_sizes=(150,), runs=2, seed=3, epochs=1, budget=TINY,
                        methods=("earth-ft", "evomerge", "modelswarm", "acomerge", "distill"))


@pytest.fixture(scope="module")
def loky_result(dataset, small_settings):
    return run_mccv(dataset, small_settings, n_jobs=2, backend="loky", progress=False)


def test_metrics_by_hand():
    y_true = np.array([0, 0, 0, 0, 1, 1, 2, 2])
    y_pred = np.array([0, 0, 0, 1, 1, 2, 2, 2])
    m = classification_metrics(y_true, y_pred)
    # recalls: 3/4, 1/2, 2/2 -> balanced accuracy 0.75
    assert m["balanced_accuracy"] == pytest.approx(0.75)
    assert m["recall"] == pytest.approx([0.75, 0.5, 1.0])
    # precisions: 3/3, 1/2, 2/3; F1 = 2PR/(P+R): 6/7, 1/2, 4/5
    assert m["precision"] == pytest.approx([1.0, 0.5, 2 / 3])
    assert m["macro_f1"] == pytest.approx((6 / 7 + 0.5 + 0.8) / 3)
    assert m["confusion_matrix"] == [[3, 1, 0], [0, 1, 1], [0, 0, 2]]
    with pytest.raises(ValueError):
        classification_metrics(y_true, y_pred[:-1])
    with pytest.raises(ValueError, match="predicted labels must be classes"):
        classification_metrics(y_true, np.array([0, 0, 0, 1, 1, 2, 2, 3]))


def test_metrics_are_scikit_learns_bit_for_bit():
    """The metrics come from one confusion matrix: every number equals scikit-learn's own function's,
    exactly, also where a class is missing from the truth, the predictions or both."""
    from sklearn.metrics import balanced_accuracy_score, f1_score, precision_recall_fscore_support

    rng = np.random.default_rng(7)
    checked = 0
    for case in range(300):
        n = int(rng.integers(1, 400))
        classes_true = rng.choice(3, size=int(rng.integers(1, 4)), replace=False)
        classes_pred = rng.choice(3, size=int(rng.integers(1, 4)), replace=False)
        y_true, y_pred = rng.choice(classes_true, n), rng.choice(classes_pred, n)
        m = classification_metrics(y_true, y_pred)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "y_pred contains classes not in y_true"
            ba = balanced_accuracy_score(y_true, y_pred)
        p, r, _, _ = precision_recall_fscore_support(y_true, y_pred, labels=[0, 1, 2], zero_division=0)
        assert m["balanced_accuracy"] == float(ba), case
        assert m["macro_f1"] == float(f1_score(y_true, y_pred, labels=[0, 1, 2], average="macro", zero_division=0)), case
        assert m["precision"] == p.tolist() and m["recall"] == r.tolist(), case
        checked += len(set(y_true.tolist())) < 3 or len(set(y_pred.tolist())) < 3
    assert checked > 100  # the cases with a class missing were exercised


def test_balanced_accuracy_alone_is_the_same_number_without_a_warning():
    """`balanced_accuracy` (realism, domain gap) is classification_metrics's figure, scikit-learn's number,
    and stays quiet where the truth lacks a predicted class (scikit-learn warns on every such call)."""
    from sklearn.metrics import balanced_accuracy_score

    y_true, y_pred = np.array([0, 0, 1, 1, 0]), np.array([0, 2, 1, 0, 0])  # class 2 never true
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ours = balanced_accuracy(y_true, y_pred)
    with warnings.catch_warnings(record=True) as theirs_said:
        warnings.simplefilter("always")
        theirs = balanced_accuracy_score(y_true, y_pred)
    assert theirs_said, "scikit-learn no longer warns here: this test's premise is gone"
    assert ours == float(theirs) == (2 / 3 + 1 / 2) / 2
    assert ours == classification_metrics(y_true, y_pred)["balanced_accuracy"]


def test_method_parsing():
    assert parse_methods(None) == list(default_methods()) == parse_methods("all")
    assert set(selectable()) - set(default_methods()) == set(registry.in_group("Noise-robust"))  # opt-in only
    assert parse_methods("distill, acomerge") == ["acomerge", "distill"]  # table order
    with pytest.raises(ValueError, match="unknown method"):
        parse_methods("acomerge,telepathy")


def test_json_layout(loky_result, small_settings):
    res = loky_result["results"]
    assert set(res) == set(small_settings.methods)
    for method, by_size in res.items():
        assert set(by_size) == {"150"}
        entry = by_size["150"]
        for metric in ("balanced_accuracy", "macro_f1"):
            assert set(entry[metric]) >= {"mean", "std"}
            runs = entry[metric]["runs"]
            assert len(runs) == 2 and all(0.0 <= v <= 1.0 for v in runs)
            assert entry[metric]["mean"] == pytest.approx(np.mean(runs))
            assert entry[metric]["std"] == pytest.approx(np.std(runs, ddof=1))
        assert len(entry["precision"]["mean"]) == 3 and len(entry["recall"]["std"]) == 3
        cm = np.array(entry["confusion_matrix"])
        # summed over 2 runs, each testing on every target row outside its 150 calibration rows
        assert cm.shape == (3, 3) and cm.sum() == 2 * entry["n_test_mean"] == 2 * (1367 - 150)
    # the AcoMerge convergence curve: one best-so-far value per generation, never rising
    curve = loky_result["convergence"]["acomerge"]["150"]["mean"]
    assert len(curve) == TINY.steps and all(b <= a for a, b in zip(curve, curve[1:]))
    test = loky_result["ttest"]["150"]["macro_f1"]
    assert test["best"] == test["ranking"][0] and test["second"] == test["ranking"][1]
    assert {"nadeau-bengio", "reference"} == set(test["tests"]) and test["n_train"] == 150
    json.dumps(loky_result)  # JSON-serialisable as is


def test_same_seed_same_numbers_sequential_vs_processes(dataset, small_settings, loky_result):
    sequential = run_mccv(dataset, small_settings, n_jobs=1, progress=False)
    assert comparable(sequential) == comparable(loky_result)


def test_dask_backend_gives_identical_results(dataset, small_settings, loky_result):
    distributed = need_module("dask.distributed", "dask")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        on_dask = run_mccv(dataset, small_settings, backend="dask", scheduler=cluster.scheduler_address,
                           progress=False)
    assert on_dask["timing"]["backend"] == "dask"
    assert comparable(on_dask) == comparable(loky_result)


def test_batched_runs_beside_cpu_jobs_give_the_same_numbers(dataset, small_settings, loky_result):
    """The GPU layout of an evaluation (AcoMerge's runs batched in this process while the other
    methods' jobs run on workers beside it), here with the CPU engine: same numbers as always."""
    beside = run_mccv(dataset, small_settings, n_jobs=2, progress=False, batch_runs=True)
    assert comparable(beside) == comparable(loky_result)


def test_timing_says_where_the_cpu_time_went(loky_result, small_settings):
    """Issue 30: the evaluation reports the CPU seconds of the source models' training and of every
    method's jobs (what `bench fusion --table-runs` reads); they add up to the total."""
    t = loky_result["timing"]
    assert set(t["sources_cpu_s"]) == {"experts"}  # no method of these needs the joint model
    assert t["sources_cpu_s"]["experts"] > 0
    assert set(t["method_cpu_s"]) == set(small_settings.methods) and all(v > 0 for v in t["method_cpu_s"].values())
    for m, total in t["method_cpu_s"].items():  # two runs per method: the mean is half the sum
        assert t["method_mean_cpu_s"][m] == pytest.approx(total / small_settings.runs)
    assert t["cpu_s"] == pytest.approx(sum(t["sources_cpu_s"].values()) + sum(t["method_cpu_s"].values()))
    assert t["jobs_without_cpu_time"] == 0
    # of a job's time, its fitness calls on D_Cal: the searches' share, none for a fine-tuning or a distillation
    fit = t["method_fitness_cpu_s"]
    assert fit["earth-ft"] == 0 and fit["distill"] == 0
    for m in ("acomerge", "evomerge", "modelswarm"):
        assert 0 < fit[m] < t["method_cpu_s"][m], m
    assert t["fitness_cpu_s"] == pytest.approx(sum(fit.values()))


def test_bench_table_bounds_the_wall_time_without_the_fitness(loky_result):
    """`bench fusion --table-runs`: the least wall time a table could take if its fitness cost nothing is
    the command's other CPU seconds over its jobs (or cores); the goal is judged for the goal's table only."""
    t = loky_result["timing"]
    process_cpu_s = t["cpu_s"] + 5.0  # start-up and pickling beside the jobs
    small = table_figures(t, 50.0, process_cpu_s, "sn-s", 2, 2)
    assert small["bound_cores"] == min(2, usable_cores())
    assert small["wall_s_bound_without_fitness"] == pytest.approx(
        (process_cpu_s - t["fitness_cpu_s"]) / small["bound_cores"], abs=0.01)
    assert small["method_fitness_cpu_s"] == {m: round(v, 2) for m, v in t["method_fitness_cpu_s"].items()}
    assert "goal" not in small
    goal = table_figures(t, 50.0, 1e4, "sn-s", 30, 2)["goal"]
    assert goal == {"wall_s": 60.0, "met": True, "within_reach_of_a_faster_fitness": False}


def test_another_seed_changes_the_search(dataset, small_settings, loky_result):
    other = run_mccv(dataset, EvalSettings(**{**small_settings.__dict__, "seed": 4}), n_jobs=2, progress=False)
    a = loky_result["results"]["acomerge"]["150"]["macro_f1"]["runs"]
    b = other["results"]["acomerge"]["150"]["macro_f1"]["runs"]
    assert a != b


def test_table_marks_best_second_and_significance():
    def entry(mean, runs):
        per_class = {"mean": [mean, 0.5, 0.25], "std": [0.01, 0.02, 0.03]}
        return {"balanced_accuracy": {"mean": mean, "std": 0.01, "runs": runs},
                "macro_f1": {"mean": mean, "std": 0.01, "runs": runs}, "precision": per_class, "recall": per_class}

    result = {
        "results": {"acomerge": {"150": entry(0.7, [])}, "earth-ft": {"150": entry(0.6, [])},
                    "model-base": {"150": entry(0.5, [])}},
        "ttest": {"150": {m: {"ranking": ["acomerge", "earth-ft", "model-base"], "significant": True}
                          for m in ("balanced_accuracy", "macro_f1")}},
        "config": {"arch": "sn-s", "protocol": "paper", "runs": 30},
    }
    table = markdown_table(result)
    main_table = table.split("Per-class")[0]
    rows = {line.split("|")[2].strip(): line for line in main_table.splitlines() if line.startswith("|")}
    assert "**0.7000 ± 0.0100**†" in rows["AcoMerge"]
    assert "<u>0.6000 ± 0.0100</u>" in rows["Earth + FullFinetune"]
    assert "**" not in rows["Model Base"] and "<u>" not in rows["Model Base"]
    assert table.index("Fine-tuned") < table.index("Merging")
    assert "| AcoMerge | 0.70 ± 0.01 | 0.70 ± 0.01 | 0.50 ± 0.02 | 0.50 ± 0.02 | 0.25 ± 0.03 |" in table


def test_evaluate_cli_end_to_end(real_data_dir, tmp_path, capsys):
    out, js = tmp_path / "out", tmp_path / "r.json"
    rc = main(["evaluate", "--data", str(real_data_dir), "--protocol", "traverse", "--runs", "2", "--cal-size", "150",
               "--epochs", "1", "--generations", "3", "--ants", "6", "--buffer-ablation", "--fleet-ablation",
               "--jobs", "2", "--json", str(js), "--out", str(out), "--no-progress"])
    assert rc == 0
    result = json.loads(js.read_text())
    assert set(result["results"]) == set(default_methods()) | {"buffer-centroid-random", "buffer-random",
                                                     "acomerge-earth-only", "acomerge-fleet-only"}
    for by_size in result["results"].values():
        assert set(by_size["150"]["balanced_accuracy"]) >= {"mean", "std"}
        assert set(by_size["150"]["macro_f1"]) >= {"mean", "std"}
    assert result["config"]["protocol"] == "traverse"
    assert json.loads((out / "results.json").read_text())["results"] == result["results"]
    table = (out / "table.md").read_text()
    assert table in capsys.readouterr().out
    for label in ("Joint + FullFinetune", "Evolutionary Merge", "Ensemble distillation", "MMAS only", "random×48",
                  "fleet experts only", "on D_Cal"):
        assert label in table
    for name in ("metrics.png", "confusion_150.png", "convergence.png", "buffer_ablation.png", "fleet_ablation.png"):
        assert (out / name).stat().st_size > 1000


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--methods", "acomerge,telepathy"], "unknown method"),
        (["--backend", "dask"], "--scheduler"),
        (["--cal-size", "5000"], "leave no test rows"),
        (["--protocol", "traverse", "--cal-size", "1200"], "traverse split needs"),
        (["--runs", "0"], "at least 1"),
        (["--finetune-lr", "0"], "fine-tuning rate positive"),
    ],
)
def test_evaluate_cli_bad_input(real_data_dir, capsys, extra, message):
    rc = main(["evaluate", "--data", str(real_data_dir), "--no-progress", "--epochs", "1", *extra])
    assert rc == 1
    err = capsys.readouterr().err
    assert "fleetlab evaluate: error:" in err and message in err


def test_evaluate_cli_missing_data_dir(tmp_path, capsys):
    assert main(["evaluate", "--data", str(tmp_path / "nowhere")]) == 1
    assert "nowhere" in capsys.readouterr().err


def test_buffer_sigma_reaches_the_run_buffer():
    import torch

    from fleetlab.fusion.methods import make_run_buffer

    experts = torch.stack([torch.zeros(543), torch.ones(543), torch.full((543,), 2.0)])
    for sigma in (0.05, 0.005):
        buf = make_run_buffer(experts, "experts", seed=0, sigma=sigma)
        assert buf.shape == (48, 543)
        noise = torch.cat([buf[(buf - c).abs().amax(dim=1) < 0.5] - c for c in (0.0, 1.0, 2.0)])
        assert abs(float(noise[noise != 0].std()) - sigma) < 0.1 * sigma


def test_fleet_ablation_buffers_hold_only_the_kept_experts():
    import torch

    from fleetlab.fusion.methods import fleet_ablation_buffer

    experts = torch.stack([torch.zeros(543), torch.ones(543), torch.full((543,), 2.0)])
    earth, buf = fleet_ablation_buffer("acomerge-earth-only", experts, seed=0)
    assert torch.equal(earth, experts[:1]) and buf.shape == (48, 543)
    assert float(buf.abs().max()) < 0.5 and torch.equal(buf[0], experts[0])
    fleet, buf = fleet_ablation_buffer("acomerge-fleet-only", experts, seed=0, sigma=0.005)
    assert torch.equal(fleet, experts[1:]) and buf.shape == (48, 543)
    nearest = (buf.unsqueeze(1) - experts[1:].unsqueeze(0)).abs().amax(dim=2).min(dim=1).values
    assert float(nearest.max()) < 0.1  # every row is a fleet expert or a copy of one
    with pytest.raises(ValueError, match="at least one fleet expert"):
        fleet_ablation_buffer("acomerge-fleet-only", experts[:1], seed=0)


def test_fleet_ablation_and_calibration_fit_in_an_evaluation(dataset):
    settings = EvalSettings(cal_sizes=(150,), runs=2, seed=3, epochs=1, budget=TINY, methods=("earth-ft",),
                            fleet_ablation=True)
    assert settings.all_methods == ("earth-ft", "acomerge", "acomerge-earth-only", "acomerge-fleet-only")
    result = run_mccv(dataset, settings, n_jobs=2, progress=False)
    res = result["results"]
    assert set(res) == set(settings.all_methods)
    runs = {m: res[m]["150"]["balanced_accuracy"]["runs"] for m in res}
    earth, both, fleet = runs["acomerge-earth-only"], runs["acomerge"], runs["acomerge-fleet-only"]
    assert earth != both and both != fleet and earth != fleet  # three different searches, pairwise
    for m in res:
        fit = res[m]["150"]["calibration_fit"]["balanced_accuracy"]
        assert 0.0 <= fit["mean"] <= 1.0 and fit["std"] >= 0.0
    # AcoMerge keeps the best model it evaluated on D_Cal, and its J never rises
    for m in ("acomerge", "acomerge-earth-only", "acomerge-fleet-only"):
        curve = result["convergence"][m]["150"]["mean"]
        assert all(b <= a for a, b in zip(curve, curve[1:]))
    table = markdown_table(result)
    assert "Fleet ablation" in table and "AcoMerge, Earth expert only" in table
    fit_rows = {line.split("|")[1].strip(): line for line in table.split("calibration rows vs")[1].splitlines()
                if line.startswith("| ") and "Method" not in line}
    gap = res["earth-ft"]["150"]["calibration_fit"]["balanced_accuracy"]["mean"] - \
        res["earth-ft"]["150"]["balanced_accuracy"]["mean"]
    assert f"{gap:+.3f}" in fit_rows["Earth + FullFinetune"]


def test_finetune_lr_reaches_earth_and_joint_finetune():
    import torch

    from fleetlab.fusion.pipeline import Sources, fuse
    from fleetlab.fusion.baselines import earth_finetune, model_from_flat
    from fleetlab.models import build, flatten

    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(60, 12)).astype(np.float32), np.arange(60) % 3
    flat = flatten(build("sn-s", seed=1)).numpy()
    src = Sources(arch="sn-s", roles=["earth"], experts=flat[None], aligned=flat[None], joint=flat, seconds={})
    budget = Budget(steps=5)
    default = fuse("earth-ft", src, x, y, seed=2, buffer_seed=0, budget=budget).flat
    by_hand = flatten(earth_finetune(model_from_flat("sn-s", torch.as_tensor(flat)), x, y, 2, steps=5))
    assert torch.equal(default, by_hand)  # default rate = the experts' 0.0035
    for method in ("earth-ft", "joint-ft"):
        slow = fuse(method, src, x, y, seed=2, buffer_seed=0, budget=Budget(steps=5, finetune_lr=1e-4)).flat
        fast = fuse(method, src, x, y, seed=2, buffer_seed=0, budget=Budget(steps=5, finetune_lr=1e-2)).flat
        moved = [float((m - torch.as_tensor(flat)).abs().max()) for m in (slow, fast)]
        assert moved[0] < moved[1]  # Adam moves each weight by about lr per step
