"""The telemetry simulator: determinism, label contract, physics sanity, scenario, CLI."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fleetlab.cli import main as cli_main
from fleetlab.data.contracts import CH, MIN_COMMANDED_DISTANCE_M, N_CHANNELS
from fleetlab.data.csvio import read_windows_csv
from fleetlab.data.dataset import load_dataset
from fleetlab.data.features import featurise
from fleetlab.data.labels import slip_class, slip_ratio
from fleetlab.data.simulator.engine import (
    ACCEL_LINEAR, ACCEL_SPECIFIC_FORCE, TraverseSpec, simulate_batch, simulate_traverse,
)
from fleetlab.data.simulator.rovers import GRAVITY_EARTH, GRAVITY_MOON, ROVERS
from fleetlab.data.simulator.scenario import scenario_specs, write_scenario
from fleetlab.data.simulator.terrain import TerrainSpec
from fleetlab.data.simulator.terramechanics import SOILS, drawbar_table, solve_slip


def _fleetlab(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "fleetlab.cli", *args], capture_output=True, text=True)


def _terrain(slope_deg: float, soil: str = "lunar_regolith", name: str = "test") -> TerrainSpec:
    # Short wavelengths, so that a 2-minute physics traverse goes both up and down hill (the
    # scenario terrains' long wavelengths can keep a short traverse on one slope).
    return TerrainSpec(name, soil, soil, 0.0, 10.0, slope_deg, wavelength_m=(2.0, 20.0))


@pytest.fixture(scope="module")
def small_scenario(tmp_path_factory) -> Path:
    return write_scenario(tmp_path_factory.mktemp("sim") / "a", seed=7, scale=0.08, raw=True)


# --- determinism ------------------------------------------------------------------------------


def test_same_seed_gives_byte_identical_files(small_scenario, tmp_path):
    again = write_scenario(tmp_path / "b", seed=7, scale=0.08)
    names = sorted(p.name for p in small_scenario.glob("*.csv"))
    assert names and names == sorted(p.name for p in again.glob("*.csv"))
    for name in names:
        assert (small_scenario / name).read_bytes() == (again / name).read_bytes(), name
    other = write_scenario(tmp_path / "c", seed=8, scale=0.08)
    assert any((small_scenario / n).read_bytes() != (other / n).read_bytes() for n in names)


def test_traverse_randomness_is_its_own(small_scenario):
    """A traverse simulated alone equals the same traverse simulated inside a batch."""
    specs = [s for _, _, s in scenario_specs(7, 0.08)]
    alone = simulate_batch(specs[:1])[0]
    in_batch = simulate_batch(specs[:3])[0]
    assert alone.meta == in_batch.meta
    # Same draws, same physics (compared over the first 30 s: vectorised maths may differ in the last bit).
    np.testing.assert_allclose(alone.samples[:1500], in_batch.samples[:1500], rtol=1e-9, atol=1e-9)
    assert not np.allclose(in_batch.samples[:1500], simulate_batch(specs[1:2])[0].samples[:1500])


# --- label contract -----------------------------------------------------------------------------


def test_rows_obey_the_label_contract(small_scenario):
    ds = load_dataset(small_scenario)
    assert ds.source == "manifest" and ds.rejected_nonfinite == 0
    for f in ds.files:
        t = f.table
        slip = slip_ratio(t.d_actual, t.d_commanded)
        np.testing.assert_array_equal(t.slip_pct, 100.0 * slip, err_msg=f.path.name)
        np.testing.assert_array_equal(t.label, slip_class(slip), err_msg=f.path.name)
        assert (t.n_samples == 100).all() and (t.duration_s == 2.0).all()


def test_windows_come_from_the_shared_featuriser(small_scenario):
    manifest = json.loads((small_scenario / "dataset.json").read_text())
    name, entry = next(iter(manifest["files"].items()))
    raw = np.load(small_scenario / entry["raw"])
    table = read_windows_csv(small_scenario / name)
    np.testing.assert_array_equal(table.features, featurise(raw["samples"]))
    d_act = raw["d_actual_step"][: 100 * len(table)].reshape(-1, 100).sum(axis=1)
    np.testing.assert_allclose(table.d_actual, d_act, rtol=1e-12)
    assert entry["rover"] in ROVERS and entry["gravity"] in (GRAVITY_EARTH, GRAVITY_MOON)
    assert entry["windows"] == len(table) and entry["class_counts"] == table.class_counts()


def test_stationary_windows_have_zero_slip(small_scenario):
    ds = load_dataset(small_scenario)
    tables = [f.table for f in ds.files]
    d_cmd = np.concatenate([t.d_commanded for t in tables])
    slip = np.concatenate([t.slip_pct for t in tables])
    still = d_cmd < MIN_COMMANDED_DISTANCE_M
    assert still.sum() >= 5, "the driver must stop long enough to fill whole windows"
    assert (slip[still] == 0.0).all()
    # Whole windows at a standstill exist: the wheels (and so the wheel-speed feature) rest.
    w_speed = np.concatenate([t.features[:, 0] for t in tables])
    assert (w_speed[still] < 0.03).sum() >= 3


# --- API ----------------------------------------------------------------------------------------


def test_simulate_traverse_api():
    tr = simulate_traverse("leo", "rille_wall", GRAVITY_MOON, 30.0, seed=3, rate_hz=20)
    assert tr.samples.shape == (600, N_CHANNELS) and tr.samples.dtype == np.float64
    assert tr.d_actual_step.shape == tr.d_cmd_step.shape == (600,)
    assert tr.rate_hz == 20 and tr.meta["rover"] == "leo" and tr.meta["gravity"] == GRAVITY_MOON
    assert np.isfinite(tr.samples).all() and (tr.d_actual_step >= 0).all() and (tr.d_cmd_step >= 0).all()
    w = tr.windows()
    assert len(w.label) == 15 and (w.n_samples == 40).all()
    # Commanded distance is measured wheel speed x radius x dt.
    np.testing.assert_allclose(tr.d_cmd_step, tr.samples[:, CH["wheel_speed"]] * 0.065 / 20)
    with pytest.raises(ValueError, match="unknown rover"):
        simulate_traverse("rover9", "rille_wall", GRAVITY_MOON, 10.0, 1)
    with pytest.raises(ValueError, match="gravity"):
        simulate_traverse("leo", "rille_wall", -1.0, 10.0, 1)
    with pytest.raises(ValueError, match="unknown soil"):
        TerrainSpec("bad", "cheese", "lunar_dust", 0.1, 5.0, 5.0)


# --- physics ------------------------------------------------------------------------------------


_SEEDS = (11, 12, 13)
_CASES = {  # name -> (terrain, gravity, seeds); all simulated in one batch
    "flat": (_terrain(2.0, "lunar_regolith", "flat"), GRAVITY_MOON, _SEEDS),
    "steep": (_terrain(12.0, "lunar_regolith", "steep"), GRAVITY_MOON, _SEEDS),
    "firm": (_terrain(6.0, "lunar_compacted", "firm"), GRAVITY_MOON, _SEEDS),
    "soft": (_terrain(6.0, "lunar_dust", "soft"), GRAVITY_MOON, _SEEDS),
    "level_moon": (_terrain(0.0, "lunar_regolith", "level"), GRAVITY_MOON, (21,)),
    "level_earth": (_terrain(0.0, "lunar_regolith", "level"), GRAVITY_EARTH, (21,)),
}


@pytest.fixture(scope="module")
def physics() -> dict[str, list]:
    keys = [(name, seed) for name, (_, _, seeds) in _CASES.items() for seed in seeds]
    specs = [TraverseSpec.make("leo", _CASES[n][0], _CASES[n][1], 120.0, seed) for n, seed in keys]
    out: dict[str, list] = {name: [] for name in _CASES}
    for (name, _), trace in zip(keys, simulate_batch(specs)):
        out[name].append(trace)
    return out


def _moving(tr):
    return tr.samples[:, CH["wheel_speed"]] > 0.5


def test_traction_solve_balances_the_required_pull():
    soil = SOILS["lunar_regolith"].as_arrays()
    load = np.full(5, 2.6)
    required = np.array([-0.3, 0.0, 0.3, 0.6, 0.9])
    st = solve_slip(required, load, 0.065, 0.07, 0.02, GRAVITY_MOON, soil)
    assert (np.diff(st.slip) > 0).all(), "more required pull must mean more slip"
    np.testing.assert_allclose(st.thrust - st.resistance, required, atol=0.02)
    thrust, resistance, z = drawbar_table(2.6, 0.065, 0.07, 0.02, GRAVITY_MOON, soil)
    assert (np.diff(z) >= 0).all() and z.min() > 0, "sinkage grows with slip"


def test_more_slope_means_more_slip_and_current(physics):
    flat, steep = physics["flat"], physics["steep"]
    slip = lambda trs: np.mean([np.abs(t.truth["slip"][_moving(t)]).mean() for t in trs])  # noqa: E731
    # Per-traverse site soils (paired by seed here) and slow soil variation add spread, so the
    # margin over a 2-minute traverse is smaller than the uphill-vs-level one below.
    assert slip(steep) > slip(flat) + 0.02
    pitch_spread = lambda trs: np.mean([t.samples[:, CH["pitch"]].std() for t in trs])  # noqa: E731
    assert pitch_spread(steep) > 3 * pitch_spread(flat)
    # Within the hilly traverses: driving uphill needs more slip and more current than level driving.
    pitch = np.concatenate([t.truth["pitch"] for t in steep])
    moving = np.concatenate([_moving(t) for t in steep])
    uphill, level = moving & (pitch > 0.12), moving & (np.abs(pitch) < 0.03)
    assert uphill.sum() > 200 and level.sum() > 200
    for key, margin in (("slip", 0.1), ("current", 0.02)):
        if key == "slip":
            v = np.concatenate([t.truth["slip"] for t in steep])
        else:
            v = np.concatenate([t.samples[:, CH["motor_current"]] for t in steep])
        assert v[uphill].mean() > v[level].mean() + margin, key


def test_softer_soil_means_more_slip_and_sinkage(physics):
    firm, soft = physics["firm"], physics["soft"]
    slip = lambda trs: np.mean([t.truth["slip"][_moving(t)].mean() for t in trs])  # noqa: E731
    sink = lambda trs: np.mean([t.truth["sinkage"][_moving(t)].mean() for t in trs])  # noqa: E731
    assert slip(soft) > slip(firm) + 0.05
    assert sink(soft) > 1.5 * sink(firm)


def test_gravity_sets_acc_z_and_sinkage(physics):
    moon, earth = physics["level_moon"][0], physics["level_earth"][0]
    # Default convention: gravity-free linear acceleration, like the Fleet-To-Lab files.
    assert abs(moon.samples[:, CH["acc_z"]].mean()) < 0.05 and abs(earth.samples[:, CH["acc_z"]].mean()) < 0.05
    assert moon.meta["accel"] == ACCEL_LINEAR
    # Raw specific force: the same traverses (same draws), with gravity in the accelerometer.
    specs = [TraverseSpec.make("leo", _CASES[n][0], _CASES[n][1], 120.0, _CASES[n][2][0])
             for n in ("level_moon", "level_earth")]
    raw_moon, raw_earth = simulate_batch(specs, accel=ACCEL_SPECIFIC_FORCE)
    assert abs(raw_moon.samples[:, CH["acc_z"]].mean() - GRAVITY_MOON) < 0.05
    assert abs(raw_earth.samples[:, CH["acc_z"]].mean() - GRAVITY_EARTH) < 0.1
    np.testing.assert_array_equal(raw_moon.truth["slip"], moon.truth["slip"])  # only the IMU convention differs
    with pytest.raises(ValueError, match="acceleration convention"):
        simulate_batch(specs, accel="gravity-ish")
    # Level ground: attitude near zero, x/y specific force near zero on average.
    assert np.abs(moon.samples[:, [CH["roll"], CH["pitch"]]].mean(axis=0)).max() < 0.02
    assert np.abs(moon.samples[:, [CH["acc_x"], CH["acc_y"]]].mean(axis=0)).max() < 0.1
    # Lower weight presses the wheels in less.
    assert moon.truth["sinkage"].mean() < 0.6 * earth.truth["sinkage"].mean()


def test_lower_gravity_means_less_friction_traction():
    """Same rover and soil: the friction term W tan(phi) of the peak thrust shrinks with g."""
    soil = SOILS["lunar_regolith"].as_arrays()
    peak = {g: drawbar_table(6.5 * g / 4, 0.065, 0.07, 0.02, g, soil)[0].max() for g in (GRAVITY_EARTH, GRAVITY_MOON)}
    assert peak[GRAVITY_MOON] < 0.3 * peak[GRAVITY_EARTH]
    # Cohesion does not scale with g, so per unit weight the Moon keeps a little more.
    weight = {g: 6.5 * g / 4 for g in peak}
    assert peak[GRAVITY_MOON] / weight[GRAVITY_MOON] > peak[GRAVITY_EARTH] / weight[GRAVITY_EARTH]


# --- scenario -----------------------------------------------------------------------------------


def test_target_moon_class_mix_matches_the_paper():
    specs = [s for role, _, s in scenario_specs(1, 1.0) if role == "target"]
    assert len(specs) >= 8
    labels = np.concatenate([t.windows().label for t in simulate_batch(specs)])
    assert 1300 <= len(labels) <= 1500
    mix = np.bincount(labels, minlength=3) / len(labels)
    np.testing.assert_allclose(mix, [0.65, 0.22, 0.13], atol=0.04)


def test_roles_differ_as_expected(small_scenario):
    ds = load_dataset(small_scenario)
    ds.check_roles()
    assert ds.roles == ["earth", "fleet_hauler", "fleet_scout", "target"]
    low = {r: ds.table(r).class_counts()[0] / len(ds.table(r)) for r in ds.roles}
    assert low["earth"] > 0.8
    assert all(low[r] < low["earth"] for r in ds.fleet_roles)
    # Gravity-free linear acceleration by default: mean acc_z near 0 in every role, Earth included.
    acc_z = {r: ds.table(r).features[:, 8].mean() for r in ds.roles}
    assert all(abs(v) < 0.1 for v in acc_z.values()), acc_z


def test_specific_force_option_puts_gravity_in_acc_z(tmp_path):
    """--accel specific-force: acc_z = g cos(pitch) cos(roll), a little below g on sloped terrain."""
    ds = load_dataset(write_scenario(tmp_path / "sf", seed=7, scale=0.03, accel=ACCEL_SPECIFIC_FORCE))
    acc_z = {r: ds.table(r).features[:, 8].mean() for r in ds.roles}
    assert 0.95 * GRAVITY_EARTH < acc_z["earth"] < GRAVITY_EARTH + 0.05
    assert all(0.85 * GRAVITY_MOON < acc_z[r] < GRAVITY_MOON + 0.02 for r in ds.roles if r != "earth")
    assert json.loads((tmp_path / "sf" / "dataset.json").read_text())["accel"] == ACCEL_SPECIFIC_FORCE


# --- CLI ----------------------------------------------------------------------------------------


def test_cli_writes_a_dataset_folder(tmp_path):
    out = tmp_path / "sim"
    r = _fleetlab("simulate", "--out", str(out), "--seed", "2", "--scale", "0.05", "--raw")
    assert r.returncode == 0, r.stderr
    assert "target" in r.stdout and "fleet_scout" in r.stdout
    ds = load_dataset(out)
    ds.check_roles()
    assert len(ds.groups("target")) == len(ds.table("target")) and len(set(ds.groups("target"))) >= 2
    assert len(list(out.glob("*.npz"))) == len(ds.files)
    meta = json.loads((out / "dataset.json").read_text())
    assert meta["seed"] == 2 and meta["scale"] == 0.05
    assert all({"rover", "terrain", "gravity", "seed"} <= set(e) for e in meta["files"].values())


def test_fleet_choice_keeps_earth_and_target_traverses(small_scenario, tmp_path):
    """--fleet swaps the fleet rovers only: Earth and target files are byte-identical, the fleet
    roles follow the chosen rovers (a sister 'leo' included), and duplicates/unknowns are refused."""
    sister = write_scenario(tmp_path / "sister", seed=7, scale=0.08, fleet=("leo", "hauler"))
    ds = load_dataset(sister)
    assert ds.roles == ["earth", "fleet_hauler", "fleet_leo", "target"]
    kept = [p.name for p in small_scenario.glob("*.csv") if not p.name.startswith("fleet_scout")]
    assert any(n.startswith("target") for n in kept) and any(n.startswith("earth") for n in kept)
    for name in kept:  # fleet_hauler keeps its seed slot too
        assert (small_scenario / name).read_bytes() == (sister / name).read_bytes(), name
    meta = json.loads((sister / "dataset.json").read_text())
    assert meta["fleet"] == ["leo", "hauler"]
    assert {e["rover"] for n, e in meta["files"].items() if n.startswith("fleet_leo")} == {"leo"}
    roles = [role for role, _, _ in scenario_specs(7, 0.08, fleet=("scout", "hauler", "leo"))]
    assert roles.count("fleet_leo") == roles.count("fleet_scout") > 0
    for bad, message in ((("leo", "leo"), "once"), (("rover9",), "one or more of"), ((), "one or more of")):
        with pytest.raises(ValueError, match=message):
            scenario_specs(7, 0.08, fleet=bad)


def test_cli_rejects_bad_options(tmp_path, capsys):
    assert cli_main(["simulate", "--out", str(tmp_path / "x"), "--scale", "0"]) == 1
    err = capsys.readouterr().err
    assert "--scale" in err and "Traceback" not in err
    assert cli_main(["simulate", "--out", str(tmp_path / "x"), "--rate", "1"]) == 1
    err = capsys.readouterr().err
    assert "samples per" in err and "Traceback" not in err
    assert not any((tmp_path / "x").glob("*.csv"))
    assert cli_main(["simulate", "--out", str(tmp_path / "x"), "--fleet", "scout,moonbuggy"]) == 1
    err = capsys.readouterr().err
    assert "moonbuggy" in err and "Traceback" not in err


def test_bench_data_json(capsys):
    assert cli_main(["bench", "data", "--json", "--samples", "100000", "--repeats", "2", "--sim-scale", "0.02"]) == 0
    out = json.loads(capsys.readouterr().out)
    # the figures are there and positive; how fast is for the benchmark's reader, not a test threshold
    assert out["featurise"]["samples_per_s"] > 0
    assert out["simulate"]["batched_sim_s_per_wall_s"] > 0


# --- realism against the real Fleet-To-Lab files (issue 17) --------------------------------------


def test_default_scenario_within_realism_bands(real_data_dir, tmp_path):
    """`fleetlab simulate` (default seed) against the real files: class mix 65/22/13 +- 4 points,
    lag-1 slip autocorrelation 0.90-0.99, same-class runs 8-22 windows, and leave-one-traverse-out
    and Earth-expert zero-shot balanced accuracy within +- 0.05 of the real files' (SN-S, seed 0).
    The full report, with Earth + FullFinetune too: `fleetlab data compare SIM REAL`."""
    from fleetlab.data.compare import persistence
    from fleetlab.evaluation.realism import earth_zero_shot, loto

    sim, real = load_dataset(write_scenario(tmp_path / "sim", seed=1)), load_dataset(real_data_dir)
    target = sim.table("target")
    mix = np.bincount(target.label, minlength=3) / len(target)
    assert np.abs(100 * mix - [65, 22, 13]).max() <= 4, mix
    p = persistence([f.table for f in sim.files_of("target")])
    assert 0.90 <= p["slip_lag1_autocorr_mean"] <= 0.99, p
    assert 8 <= p["mean_run_length"] <= 22, p
    for name, measure in (("leave-one-traverse-out", lambda ds: float(np.mean(loto(ds)))),
                          ("Earth zero-shot", earth_zero_shot)):
        s, r = measure(sim), measure(real)
        print(f"{name}: simulator {s:.3f}, real files {r:.3f}")
        assert abs(s - r) <= 0.05, (name, s, r)
