"""Calibration labels that say how sure they are (issue 46): the class probabilities of a VO reading, the
fitness that takes them as targets, and `acomerge-vo`, which fuses on them."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from fleetlab.cli import main
from fleetlab.data.csvio import read_windows_csv
from fleetlab.data.label_noise import LabelNoise, VoModel, read_vo_readings, vo_calibration_labels, vo_class_probabilities
from fleetlab.data.labels import slip_class, slip_ratio
from fleetlab.evaluation.protocol import EvalSettings, Target, run_jobs
from fleetlab.fusion import registry
from fleetlab.fusion.fitness import CalibrationFitness
from fleetlab.fusion.pipeline import Sources
from fleetlab.fusion.registry import Budget, FusedModel
from fleetlab.models import build, flatten, load_flat, load_model
from fleetlab.models.train import class_weights

from small_models import fusion_inputs


def _readings(n=500, seed=0):
    rng = np.random.default_rng(seed)
    d_cmd = rng.uniform(0.1, 1.0, n)
    measured = d_cmd * rng.uniform(0.2, 1.8, n)  # every class, and many windows near a threshold
    return measured, d_cmd


def test_probabilities_are_those_of_the_true_distance_under_the_vo_error():
    """Sampling the true distance around the measured one with VO's error, and classing each sample as exact
    labels are classed, gives the same shares as the closed form."""
    measured, d_cmd = _readings()
    vo = VoModel().scaled(5.0)
    probs = vo_class_probabilities(measured, d_cmd, np.zeros(measured.size, bool), vo)
    draws = measured[:, None] + vo.error_sigma(measured)[:, None] * np.random.default_rng(1).standard_normal(
        (measured.size, 20000))
    classes = slip_class(slip_ratio(draws, d_cmd[:, None]))
    sampled = np.stack([(classes == c).mean(axis=1) for c in range(3)], axis=1)
    np.testing.assert_allclose(probs, sampled, atol=0.02)
    np.testing.assert_allclose(probs.sum(axis=1), 1.0, atol=1e-12)
    assert ((probs > 0.05) & (probs < 0.95)).any(axis=1).mean() > 0.1  # not all certain: the test can fail


def test_an_exact_reading_is_its_class_a_dropout_is_no_label_and_a_standstill_is_low():
    measured, d_cmd = _readings(60)
    exact = vo_class_probabilities(measured, d_cmd, np.zeros(60, bool), VoModel().scaled(0.0))
    np.testing.assert_array_equal(exact, np.eye(3)[slip_class(slip_ratio(measured, d_cmd))])
    dropped = np.arange(60) % 4 == 0
    probs = vo_class_probabilities(measured, d_cmd, dropped, VoModel().scaled(3.0))
    assert np.all(probs[dropped] == 0) and np.allclose(probs[~dropped].sum(axis=1), 1.0)
    still = vo_class_probabilities(np.array([0.01]), np.array([0.02]), np.array([False]), VoModel().scaled(3.0))
    np.testing.assert_array_equal(still, [[1.0, 0.0, 0.0]])  # commanded < 5 cm: slip 0 by definition


def _windows(n=600, seed=3):
    rng = np.random.default_rng(seed)
    d_cmd = rng.uniform(0.2, 0.6, n)
    d_act = d_cmd * (1 - rng.uniform(-0.1, 0.9, n))
    return d_act, d_cmd, np.repeat(np.arange(n // 100), 100), slip_class(slip_ratio(d_act, d_cmd))


def test_the_probabilities_come_from_the_reading_that_made_the_labels():
    d_act, d_cmd, groups, y = _windows()
    noise = LabelNoise("vo", 3.0)
    labels, probs = noise.apply_with_probabilities(y, np.random.default_rng(4), d_act, d_cmd, groups)
    assert np.array_equal(labels, noise.apply(y, np.random.default_rng(4), d_act, d_cmd, groups))
    dropped = probs.sum(axis=1) == 0
    assert 0 < dropped.sum() < 0.5 * y.size and np.all(labels[dropped] == 0)  # a dropout keeps the wheels: low
    certain = probs.max(axis=1) == 1.0
    assert certain.any() and np.array_equal(labels[certain], probs[certain].argmax(axis=1))
    # VO's class is the likeliest one when the reading is far from a threshold, not always near one
    assert np.mean(probs[~dropped].argmax(axis=1) == labels[~dropped]) > 0.9
    for kind in ("adjacent", "symmetric"):  # a flip comes with no reading
        assert LabelNoise(kind, 0.2).apply_with_probabilities(y, np.random.default_rng(4))[1] is None


def test_soft_targets_fitness_is_the_expected_loss_with_the_labels_weights():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(60, 12)).astype(np.float32)
    y = rng.integers(0, 3, 60)
    t = rng.dirichlet(np.ones(3), 60)
    flats = torch.stack([flatten(build("sn-s", seed=s)) for s in range(4)])
    got = CalibrationFitness("sn-s", x, y, targets=t)(flats)
    w = class_weights(y)[torch.from_numpy(y)].double()
    for flat, j in zip(flats, got):
        with torch.no_grad():
            logp = torch.log_softmax(load_flat(build("sn-s"), flat).eval()(torch.from_numpy(x)), 1).double()
        want = -(w * (torch.from_numpy(t) * logp).sum(1)).sum() / w.sum()
        torch.testing.assert_close(j.double(), want, rtol=1e-5, atol=1e-6)
    # certain targets of the labels' own classes are the labels: the same bits as the plain fitness
    assert torch.equal(CalibrationFitness("sn-s", x, y, targets=np.eye(3)[y])(flats), CalibrationFitness("sn-s", x, y)(flats))


@pytest.mark.parametrize("bad, match", [
    (np.full((60, 3), 0.5), "summing to 1"), (np.full((60, 3), np.nan), "summing to 1"),
    (np.eye(3)[np.zeros(59, int)], r"\(60, 3\)"), (np.tile([1.5, -0.5, 0.0], (60, 1)), "non-negative"),
])
def test_bad_class_probabilities_are_one_clear_error(bad, match):
    x = np.zeros((60, 12), np.float32)
    with pytest.raises(ValueError, match=match):
        CalibrationFitness("sn-s", x, np.zeros(60, np.int64), targets=bad)
    with pytest.raises(ValueError, match="hard labels"):
        CalibrationFitness("sn-s", x, np.zeros(60, np.int64), loss="gce", targets=np.eye(3)[np.zeros(60, int)])


def _inputs(probs):
    return fusion_inputs(Budget(steps=3, ants=8), y_cal_probs=probs)


def test_acomerge_vo_is_acomerge_on_certain_labels_and_leaves_out_the_unmeasured():
    plain = registry.fit("acomerge", _inputs(None))
    certain = registry.fit("acomerge-vo", _inputs(lambda y: np.eye(3)[y]))
    assert torch.equal(certain.flat, plain.flat) and certain.details["vo"]["rows_without_measurement"] == 0

    def unsure(y):
        p = 0.6 * np.eye(3)[y] + 0.4 * np.eye(3)[(y + 1) % 3]
        p[::10] = 0  # every tenth window: VO did not converge
        return p
    fused = registry.fit("acomerge-vo", _inputs(unsure))
    assert fused.details["vo"] == {"rows_without_measurement": 9, "of": 90}
    assert fused.details["best_fitness"] != plain.details["best_fitness"]
    with pytest.raises(ValueError, match="vo:SCALE"):
        registry.fit("acomerge-vo", _inputs(None))
    with pytest.raises(ValueError, match="VO did not converge on any of D_Cal's 90 windows"):
        registry.fit("acomerge-vo", _inputs(lambda y: np.zeros((y.size, 3))))


def test_evaluate_refuses_acomerge_vo_on_flips_without_a_reading_before_any_work():
    with pytest.raises(ValueError, match="acomerge-vo.*adjacent:0.2"):
        EvalSettings(cal_sizes=(150,), runs=1, methods=("acomerge", "acomerge-vo"), label_noise="adjacent:0.2")
    for noise in ("", "vo:1"):
        EvalSettings(cal_sizes=(150,), runs=1, methods=("acomerge-vo",), label_noise=noise)
    assert "acomerge-vo" in registry.selectable() and "acomerge-vo" not in registry.default_methods()


@pytest.fixture()
def spy():
    seen = []

    def fit(inp):
        seen.append(inp.y_cal_probs)
        return FusedModel("spy", inp.arch, flatten(build("sn-s", seed=0)))

    registry.register("spy-probs", fit, group="Test")
    yield seen
    registry.unregister("spy-probs")


def test_every_draw_hands_its_labels_probabilities_to_the_methods(spy):
    d_act, d_cmd, groups, y = _windows()
    target = Target(x=np.random.default_rng(3).normal(size=(600, 12)).astype(np.float32), y=y, groups=groups,
                    d_actual=d_act, d_commanded=d_cmd, duration_s=np.full(600, 2.0))
    src = Sources("sn-s", ["earth", "a", "b"], *[torch.stack([flatten(build("sn-s", seed=s)) for s in range(3)]).numpy()] * 2,
                  None, {})
    jobs = {noise: run_jobs(150, [0], "spy-probs", src, target, EvalSettings(
        cal_sizes=(150,), runs=1, methods=("acomerge",), label_noise=noise))[0] for noise in ("", "vo:3", "adjacent:0.2")}
    exact, vo, adjacent = spy
    assert exact.shape == (150, 3) and np.all(exact.max(axis=1) == 1.0)  # exact labels are certain
    assert vo.shape == (150, 3) and (vo.max(axis=1) < 1.0).any()
    assert jobs["vo:3"]["label_noise"]["vo_dropouts"] == int((vo.sum(axis=1) == 0).sum()) > 0
    assert adjacent is None and "vo_dropouts" not in jobs["adjacent:0.2"]["label_noise"]


@pytest.fixture(scope="module")
def sim_vo(tmp_path_factory):
    """The simulator's small dataset with NAME.vo_labels.csv beside each traverse."""
    out = tmp_path_factory.mktemp("sim") / "data"
    assert main(["simulate", "--out", str(out), "--scale", "0.1", "--labels", "vo"]) == 0
    return out


def _fuse(sim_vo, out, *extra):
    cal = sorted(sim_vo.glob("target_*.csv"))
    cal = [p for p in cal if not p.name.endswith(".vo_labels.csv")][0]
    return cal, main(["fuse", "--data", str(sim_vo), "--calibration", str(cal), "--out", str(out), "--epochs", "2",
                      "--generations", "3", "--ants", "12", "--no-progress", "--threads", "1", *extra])


def test_fuse_labels_d_cal_by_the_vo_file_and_acomerge_vo_fits_its_readings(sim_vo, tmp_path, capsys):
    cal, _ = _fuse(sim_vo, tmp_path / "probe", "--method", "earth-ft")
    vo_file = cal.with_name(cal.stem + ".vo_labels.csv")
    readings = np.genfromtxt(vo_file, delimiter=",", names=True)
    assert _fuse(sim_vo, tmp_path / "run", "--method", "acomerge-vo", "--vo-labels", str(vo_file))[1] == 0
    _, meta = load_model(tmp_path / "run" / "fused.pt")
    labels = meta["calibration"]["labels"]
    assert labels["vo_dropouts"] == int(readings["vo_dropout"].sum()) > 0
    assert labels["differ_from_file_labels"] == int((readings["slip_class_vo"] != readings["slip_class"]).sum())
    assert "VO did not converge on" in (tmp_path / "run" / "report.md").read_text()
    # the report's CE is the plain weighted CE on VO's classes (not the search's objective on the measured rows)
    model, _ = load_model(tmp_path / "run" / "fused.pt")
    x = read_windows_csv(cal).features.astype(np.float32)
    ce = float(CalibrationFitness("sn-s", x, readings["slip_class_vo"].astype(np.int64))(flatten(model)))
    assert meta["fitness"] == pytest.approx(ce, rel=1e-5)
    assert json.loads((tmp_path / "run" / "history.json").read_text())["method"] == "acomerge-vo"
    capsys.readouterr()
    # without VO's readings acomerge-vo has nothing to fit: refused before the experts train
    assert _fuse(sim_vo, tmp_path / "no", "--method", "acomerge-vo")[1] == 1
    assert "--vo-labels" in capsys.readouterr().err and not (tmp_path / "no").exists()


@pytest.mark.parametrize("edit, match", [
    (lambda rows: rows[:-1], "VO readings for the"),
    (lambda rows: [rows[0], rows[1].rstrip().rsplit(",", 1)[0] + ",2\n", *rows[2:]], "is not 0 or 1"),  # vo_dropout last
    (lambda rows: [rows[0].replace("total_dist_vo", "dist"), *rows[1:]], "missing"),
])
def test_a_bad_vo_file_is_one_clear_error(sim_vo, tmp_path, capsys, edit, match):
    cal = [p for p in sorted(sim_vo.glob("target_*.csv")) if not p.name.endswith(".vo_labels.csv")][0]
    rows = cal.with_name(cal.stem + ".vo_labels.csv").read_text().splitlines(keepends=True)
    bad = tmp_path / "bad.vo_labels.csv"
    bad.write_text("".join(edit(rows)))
    assert _fuse(sim_vo, tmp_path / "run", "--vo-labels", str(bad))[1] == 1
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err


def test_a_vo_file_written_by_another_tool_reads_by_column_name(tmp_path):
    """pandas' CSV (LF line ends, other columns first and between, the dropout's distance left empty) gives the
    same readings as the rows it was written from."""
    import pandas as pd

    frame = pd.DataFrame({"t_s": [0.0, 2.0, 4.0], "vo_dropout": [0, 1, 0], "note": ["a", "b", "c"],
                          "total_dist_vo": [0.41, None, 0.305]})
    frame.to_csv(tmp_path / "mine.csv", index=False)
    measured, dropped = read_vo_readings(tmp_path / "mine.csv")
    np.testing.assert_array_equal(dropped, [False, True, False])
    np.testing.assert_array_equal(measured[~dropped], [0.41, 0.305])
    assert np.isnan(measured[1])
    labels, probs = vo_calibration_labels(measured, dropped, np.array([0.4, 0.4, 0.4]), VoModel())
    assert labels[1] == 0 and np.all(probs[1] == 0) and np.all(np.isfinite(probs))  # the dropout: low, no label
