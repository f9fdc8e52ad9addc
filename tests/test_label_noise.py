"""Noisy calibration labels (issue 46): the noise models, that they touch D_Cal only and are reproducible by
seed, the noise-robust methods and the sweep's table."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from fleetlab.cli import main
from fleetlab.data.label_noise import LabelNoise, VoModel
from fleetlab.data.labels import slip_class, slip_ratio
from fleetlab.evaluation import noise_sweep
from fleetlab.evaluation.protocol import EvalSettings, Target, run_jobs
from fleetlab.fusion import registry
from fleetlab.fusion.fitness import CalibrationFitness
from fleetlab.fusion.label_audit import flag_labels
from fleetlab.fusion.pipeline import Sources
from fleetlab.fusion.registry import Budget, FusedModel
from fleetlab.models import build, flatten, load_flat
from fleetlab.models.train import adjacent_transition, class_weights, weighted_ce, weighted_forward_ce, weighted_gce

from small_models import fusion_inputs

N = 20000


def _labels(seed=0, n=N):
    return np.random.default_rng(seed).integers(0, 3, n)


@pytest.mark.parametrize("kind", ["symmetric", "adjacent"])
def test_rate_is_the_share_of_labels_changed(kind):
    y = _labels()
    for rate in (0.0, 0.1, 0.3):
        noisy = LabelNoise(kind, rate).apply(y, np.random.default_rng(1))
        assert abs(np.mean(noisy != y) - rate) < 0.012, (kind, rate)
    noisy = LabelNoise(kind, 1.0).apply(y, np.random.default_rng(1))
    assert np.all(noisy != y)
    if kind == "adjacent":  # only to a neighbouring class: low and high never swap
        assert np.all(np.abs(noisy - y) == 1)
    else:  # both other classes, about equally often
        for c in range(3):
            to = noisy[y == c]
            counts = np.bincount(to, minlength=3)
            assert counts[c] == 0 and abs(counts[(c + 1) % 3] - counts[(c + 2) % 3]) < 0.1 * len(to)


def test_noise_is_reproducible_by_seed():
    y = _labels(n=500)
    a = LabelNoise("symmetric", 0.2).apply(y, np.random.default_rng(7))
    b = LabelNoise("symmetric", 0.2).apply(y, np.random.default_rng(7))
    c = LabelNoise("symmetric", 0.2).apply(y, np.random.default_rng(8))
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def _windows(n=4000, seed=0):
    rng = np.random.default_rng(seed)
    d_cmd = rng.uniform(0.2, 0.6, n)
    d_act = d_cmd * (1 - rng.uniform(-0.1, 0.9, n))
    groups = np.repeat(np.arange(n // 100), 100)
    return d_act, d_cmd, groups, slip_class(slip_ratio(d_act, d_cmd))


def test_vo_at_scale_zero_gives_the_exact_labels_and_at_one_mostly_neighbours():
    d_act, d_cmd, groups, y = _windows()
    exact = LabelNoise("vo", 0.0).apply(y, np.random.default_rng(0), d_act, d_cmd, groups)
    assert np.array_equal(exact, y)
    noisy = LabelNoise("vo", 1.0).apply(y, np.random.default_rng(0), d_act, d_cmd, groups)
    changed = noisy != y
    assert 0.02 < changed.mean() < 0.5
    # a dropout keeps the wheel odometry (no slip: low); otherwise VO errs by a few percent: a neighbour
    assert np.mean(np.abs(noisy - y)[changed] == 1) > 0.6
    more = LabelNoise("vo", 3.0).apply(y, np.random.default_rng(0), d_act, d_cmd, groups)
    assert (more != y).mean() > changed.mean()


def test_vo_dropouts_keep_the_wheel_odometry():
    d_act, d_cmd, groups, y = _windows()
    always = VoModel(drift=0, scale_sigma=0, dropout=1.0, lag_s=0, resolution_m=0)
    noisy = LabelNoise("vo", 1.0).apply(y, np.random.default_rng(0), d_act, d_cmd, groups, vo=always)
    assert np.all(noisy == 0)  # VO never converged: the rover believes its wheels, slip 0


def test_vo_needs_the_distances():
    with pytest.raises(ValueError, match="travelled and commanded distance"):
        LabelNoise("vo", 1.0).apply(_labels(n=10), np.random.default_rng(0))


@pytest.mark.parametrize("text", ["adjacent", "telepathy:0.1", "adjacent:x", "symmetric:1.5", "vo:-1"])
def test_bad_noise_option_is_one_clear_error(text):
    with pytest.raises(ValueError, match="label noise"):
        LabelNoise.parse(text)


def _target(n=600, seed=3):
    rng = np.random.default_rng(seed)
    d_act, d_cmd, groups, y = _windows(n, seed)
    x = rng.normal(size=(n, 12)).astype(np.float32)
    return Target(x=x, y=y, groups=groups, d_actual=d_act, d_commanded=d_cmd, duration_s=np.full(n, 2.0))


@pytest.fixture()
def spy():
    """A throw-away method that records the labels it was given; its model predicts from the inputs."""
    seen = []

    def fit(inp):
        seen.append(inp.y_cal.copy())
        return FusedModel("spy", inp.arch, flatten(build("sn-s", seed=0)))

    registry.register("spy-noise", fit, group="Test")
    yield seen
    registry.unregister("spy-noise")


def _sources():
    flats = torch.stack([flatten(build("sn-s", seed=s)) for s in range(3)]).numpy()
    return Sources("sn-s", ["earth", "fleet_a", "fleet_b"], flats, flats, None, {})


@pytest.mark.parametrize("noise", ["adjacent:0.3", "symmetric:0.2", "vo:2"])
def test_noise_reaches_d_cal_only_and_is_the_same_for_every_method_of_a_draw(spy, noise):
    target, src = _target(), _sources()
    exact = EvalSettings(cal_sizes=(150,), runs=1, methods=("earth-ft",), budget=Budget(steps=1, ants=2))
    noisy = EvalSettings(cal_sizes=(150,), runs=1, methods=("earth-ft",), budget=Budget(steps=1, ants=2),
                         label_noise=noise)
    clean_job = run_jobs(150, [0], "spy-noise", src, target, exact)[0]
    job = run_jobs(150, [0], "spy-noise", src, target, noisy)[0]
    again = run_jobs(150, [0], "spy-noise", src, target, noisy)[0]
    run1 = run_jobs(150, [1], "spy-noise", src, target, noisy)[0]
    y_exact, y_noisy, y_again, y_run1 = spy
    assert np.array_equal(y_noisy, y_again)  # reproducible: the same seed, the same labels
    changed = int((y_noisy != y_exact).sum())
    assert changed > 0 and job["label_noise"]["corrupted"] == changed and job["label_noise"]["of"] == 150
    assert "label_noise" not in clean_job and "label_noise" in run1
    # the test rows are scored against their exact labels: the same scores as without noise (same model)
    for key in ("balanced_accuracy", "macro_f1", "confusion_matrix"):
        assert job[key] == clean_job[key], key


def test_gce_loss_matches_its_formula_and_the_fitness_uses_it():
    gen = torch.Generator().manual_seed(0)
    logits, y = torch.randn(50, 3, generator=gen), torch.randint(0, 3, (50,), generator=gen)
    w = torch.tensor([1.0, 2.0, 0.5])
    p = torch.softmax(logits, 1)[torch.arange(50), y]
    expected = (w[y] * (1 - p**0.7) / 0.7).sum() / w[y].sum()
    torch.testing.assert_close(weighted_gce(logits, y, w), expected)
    x = np.random.default_rng(0).normal(size=(60, 12)).astype(np.float32)
    yy = np.random.default_rng(1).integers(0, 3, 60)
    flats = torch.stack([flatten(build("sn-s", seed=s)) for s in range(4)])
    ce, gce = CalibrationFitness("sn-s", x, yy)(flats), CalibrationFitness("sn-s", x, yy, loss="gce")(flats)
    assert not torch.allclose(ce, gce) and torch.all(gce <= 1 / 0.7)  # bounded, unlike CE


def test_audit_flags_labels_the_predictions_contradict():
    rng = np.random.default_rng(0)
    y = rng.integers(0, 3, 300)
    probs = np.full((300, 3), 0.05)
    probs[np.arange(300), y] = 0.9  # confident, right predictions of the true labels
    noisy = y.copy()
    wrong = rng.choice(300, 30, replace=False)
    noisy[wrong] = (y[wrong] + 1) % 3
    flagged = flag_labels(noisy, probs)
    assert set(np.flatnonzero(flagged)) == set(wrong)


def test_adjacent_transition_matches_the_noise_model():
    """T[i, j] = P(label j | true i) of `adjacent:RATE`: rows sum to 1, low and high never swap, and the
    frequencies that LabelNoise.apply draws agree with it."""
    t = adjacent_transition(0.3)
    torch.testing.assert_close(t.sum(dim=1), torch.ones(3))
    assert t[0, 2] == 0 and t[2, 0] == 0 and t[1, 0] == t[1, 2]
    y = _labels()
    noisy = LabelNoise("adjacent", 0.3).apply(y, np.random.default_rng(2))
    seen = np.array([np.bincount(noisy[y == i], minlength=3) / np.sum(y == i) for i in range(3)])
    assert np.abs(seen - t.numpy()).max() < 0.02
    torch.testing.assert_close(adjacent_transition(0.0), torch.eye(3))
    with pytest.raises(ValueError, match="noise rate"):
        adjacent_transition(1.0)


def test_forward_corrected_loss_matches_its_formula_and_is_ce_at_rate_zero():
    gen = torch.Generator().manual_seed(0)
    logits, y = torch.randn(50, 3, generator=gen), torch.randint(0, 3, (50,), generator=gen)
    w = torch.tensor([1.0, 2.0, 0.5])
    q = (torch.softmax(logits, 1) @ adjacent_transition(0.2))[torch.arange(50), y]  # (Tᵀ p)_ỹ
    torch.testing.assert_close(weighted_forward_ce(logits, y, w, 0.2), -(w[y] * q.log()).sum() / w[y].sum())
    torch.testing.assert_close(weighted_forward_ce(logits, y, w, 0.0), weighted_ce(logits, y, w))
    # a confident contradiction stays finite: log (Tᵀ p)_ỹ as a logsumexp, not the log of an underflowed sum
    far = torch.tensor([[0.0, -200.0, 200.0]])
    assert torch.isfinite(weighted_forward_ce(far, torch.tensor([0]), w, 0.2))


def test_forward_correction_recovers_the_exact_posterior_from_noisy_labels():
    """Why forward correction: fitted to labels drawn from Tᵀ p*, its optimum is p* itself, where CE's optimum
    is the noisy distribution Tᵀ p*. Minimise both over one row's logits on the expected noisy labels."""
    clean = torch.tensor([0.7, 0.25, 0.05])
    noisy = clean @ adjacent_transition(0.2)
    fitted = {}
    for name, rate in (("ce", 0.0), ("fc", 0.2)):
        z = torch.zeros(1, 3, requires_grad=True)
        opt = torch.optim.Adam([z], lr=0.05)
        for _ in range(800):  # the expected loss: label c with weight P(ỹ = c)
            opt.zero_grad()
            weighted_forward_ce(z.expand(3, 3), torch.arange(3), noisy, rate).backward()
            opt.step()
        fitted[name] = torch.softmax(z.detach(), 1)[0]
    torch.testing.assert_close(fitted["fc"], clean, atol=5e-3, rtol=0)
    torch.testing.assert_close(fitted["ce"], noisy, atol=5e-3, rtol=0)
    assert (fitted["ce"] - clean).abs().max() > 0.05  # CE learns the noise


def test_forward_corrected_fitness_is_the_loss_of_each_model():
    x = np.random.default_rng(0).normal(size=(60, 12)).astype(np.float32)
    y = np.random.default_rng(1).integers(0, 3, 60)
    flats = torch.stack([flatten(build("sn-s", seed=s)) for s in range(4)])
    got = CalibrationFitness("sn-s", x, y, loss="fc", noise_rate=0.3)(flats)
    for flat, j in zip(flats, got):
        with torch.no_grad():
            logits = load_flat(build("sn-s"), flat).eval()(torch.from_numpy(x))
        torch.testing.assert_close(j, weighted_forward_ce(logits, torch.from_numpy(y), class_weights(y), 0.3),
                                   rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(CalibrationFitness("sn-s", x, y, loss="fc", noise_rate=0.0)(flats),
                               CalibrationFitness("sn-s", x, y)(flats), rtol=1e-6, atol=1e-7)


def _small_inputs(noise_rate, seed=1):
    return fusion_inputs(Budget(steps=3, ants=8, noise_rate=noise_rate), seed)


def test_the_assumed_noise_rate_reaches_the_forward_corrected_search():
    """acomerge-fc assuming no noise is AcoMerge itself (the same fitness, hence the same search); assuming
    some, it searches another objective. The budget's noise_rate is what reaches the fitness."""
    plain = registry.fit("acomerge", _small_inputs(0.0))
    assert torch.equal(registry.fit("acomerge-fc", _small_inputs(0.0)).flat, plain.flat)
    corrected = registry.fit("acomerge-fc", _small_inputs(0.3))
    assert corrected.details["config"]["loss"] == "fc" and corrected.details["config"]["noise_rate"] == 0.3
    assert corrected.details["best_fitness"] != plain.details["best_fitness"]


def test_earth_ft_fc_and_acomerge_robust_fc_fine_tune_on_the_corrected_loss():
    a, b = registry.fit("earth-ft-fc", _small_inputs(0.3)), registry.fit("earth-ft", _small_inputs(0.3))
    assert not torch.allclose(a.flat, b.flat)
    robust = registry.fit("acomerge-robust-fc", _small_inputs(0.3))
    assert robust.method == "acomerge-robust-fc" and robust.details["config"]["loss"] == "fc"
    assert torch.isfinite(robust.flat).all() and robust.flat.shape == b.flat.shape


def test_bad_assumed_noise_rate_is_refused():
    with pytest.raises(ValueError, match="noise-rate"):
        EvalSettings(cal_sizes=(150,), runs=1, methods=("acomerge-fc",), budget=Budget(noise_rate=1.0))


def test_robust_methods_are_opt_in():
    for name in ("earth-ft-gce", "acomerge-gce", "acomerge-audit", "earth-ft-fc", "acomerge-fc", "acomerge-robust-fc"):
        assert name in registry.selectable() and name not in registry.default_methods()


def test_sweep_parsing():
    assert noise_sweep.parse_sweep("adjacent:0,0.1,0.2") == ("adjacent", [0.0, 0.1, 0.2])
    for bad in ("adjacent", "x:0.1", "vo:a,b", "adjacent:0.1,0.1"):
        with pytest.raises(ValueError, match="label-noise-sweep"):
            noise_sweep.parse_sweep(bad)


def test_sweep_cli_writes_table_plot_and_json(real_data_dir, tmp_path, capsys):
    out = tmp_path / "sweep"
    rc = main(["evaluate", "--data", str(real_data_dir), "--runs", "2", "--cal-size", "150", "--epochs", "1",
               "--generations", "3", "--ants", "6", "--methods", "acomerge,earth-ft,earth-ft-gce",
               "--label-noise-sweep", "adjacent:0,0.3", "--jobs", "2", "--out", str(out), "--no-progress"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "| Method | adjacent 0 | adjacent 0.3 |" in text
    corrupted = [float(c.strip(" %")) for c in text.split("| labels corrupted |")[1].splitlines()[0].split("|")[:-1]]
    assert corrupted[0] == 0.0 and 20.0 < corrupted[1] < 40.0  # about 30 % of 2 x 150 labels
    assert (out / "sweep.png").stat().st_size > 10_000 and (out / "sweep.json").is_file()
    assert (out / "adjacent-0.3" / "runs").is_dir()


def test_simulate_writes_vo_labels_beside_the_true_ones(tmp_path, capsys):
    from fleetlab.data.csvio import read_windows_csv

    for run in ("a", "b"):
        assert main(["simulate", "--out", str(tmp_path / run), "--scale", "0.05", "--labels", "vo"]) == 0
    assert "visual odometry gives another class" in capsys.readouterr().out
    files = sorted((tmp_path / "a").glob("*.vo_labels.csv"))
    assert files and len(files) == len(list((tmp_path / "a").glob("*.csv"))) - len(files)
    wrong = 0
    for f in files:
        assert f.read_bytes() == (tmp_path / "b" / f.name).read_bytes()  # reproducible by seed
        vo = np.genfromtxt(f, delimiter=",", names=True)
        table = read_windows_csv(f.with_name(f.name.replace(".vo_labels", "")))
        assert np.array_equal(vo["slip_class"].astype(int), table.label)  # the true label beside the VO one
        wrong += int((vo["slip_class"] != vo["slip_class_vo"]).sum())
        dropped = vo["vo_dropout"] == 1
        assert np.all(vo["slip_class_vo"][dropped] == 0)  # no VO: the wheels' own distance, no slip seen
    assert wrong > 0


def test_a_model_fused_on_noisy_labels_exports_and_runs_bit_exact(tmp_path):
    """Onboard nothing changes: AcoMerge with the GCE fitness on adjacent-noisy labels gives an ordinary SN-S
    that exports and whose C kernels match the torch integer reference on every vector."""
    import subprocess

    from c_check import build_check, check_argv
    from required import need_tool

    from fleetlab.export.bundle import export_bundle
    from fleetlab.fusion.registry import FusionInputs
    from fleetlab.models import load_flat

    rng = np.random.default_rng(5)
    x = rng.normal(size=(150, 12)).astype(np.float32) * np.float32(0.5) + np.float32(1.0)
    y = np.digitize(x[:, 3], [0.8, 1.3]).astype(np.int64)
    y_noisy = LabelNoise("adjacent", 0.2).apply(y, np.random.default_rng(6))
    flats = torch.stack([flatten(build("sn-s", seed=s)) for s in range(3)])
    inp = FusionInputs("sn-s", ("earth", "a", "b"), flats, flats, None, x, y_noisy, seed=1, buffer_seed=2,
                       budget=Budget(steps=4, ants=8))
    fused = registry.fit("acomerge-gce", inp)
    bundle = tmp_path / "bundle"
    export_bundle(load_flat(build("sn-s"), fused.flat).eval(), bundle, inputs=x)
    exe = build_check(bundle, tmp_path, need_tool("gcc"), [])
    res = subprocess.run(check_argv(exe, bundle), capture_output=True, text=True, timeout=120)
    assert res.returncode == 0 and "q mismatches 0" in res.stdout, res.stdout + res.stderr
