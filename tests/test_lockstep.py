"""The accelerator path of AcoMerge (fusion/lockstep.py), checked on the CPU: dense ant
construction against the reference's, the stacked fitness against CalibrationFitness, R runs
batched against each run alone, the engine against the reference search, and `--device cuda`
refused in one line where no GPU exists."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from fleetlab.cli import main
from fleetlab.compute import resolve_device
from fleetlab.fusion.acomerge import AcoMergeConfig, acomerge, checked_inputs, construct_ants
from fleetlab.fusion.bench import synthetic_calibration
from fleetlab.fusion.finetune import finetune
from fleetlab.fusion.fitness import CalibrationFitness
from fleetlab.fusion.lockstep import (
    StackedFitness,
    construct_ants_dense,
    run_acomerge_many,
    search_lockstep,
)
from fleetlab.models import build, flatten

TINY = AcoMergeConfig(n_ants=24, generations=12, iwoa_every=4, gb_every=3)
NO_GPU = not torch.cuda.is_available()


@pytest.fixture(scope="module")
def cals():
    return [synthetic_calibration(60, seed=s) for s in range(3)]


@pytest.fixture(scope="module")
def experts(cals):
    x, y = cals[0]
    return torch.stack([flatten(finetune(build("sn-s", seed=k), x, y, steps=10, seed=k)) for k in range(3)])


@pytest.mark.parametrize("q0", [0.3, 0.95])
def test_dense_construction_takes_the_reference_paths(q0):
    tau = torch.rand(200, 12, generator=torch.Generator().manual_seed(1)) + 0.2
    eta = torch.rand(200, 12, generator=torch.Generator().manual_seed(2)) + 0.5
    ref, _ = construct_ants(tau, eta, q0, 50, torch.Generator().manual_seed(7), alpha=1.5, beta=2.0)
    dense = construct_ants_dense(tau.unsqueeze(0), eta.unsqueeze(0), q0, 50, [torch.Generator().manual_seed(7)],
                                 alpha=1.5, beta=2.0)[0]
    assert torch.equal(ref.long(), dense)
    assert (dense != tau.argmax(dim=1)).any()  # some ants did leave the greedy path


@pytest.mark.parametrize("arch", ["sn-s", "sn-d"])
def test_stacked_fitness_equals_calibration_fitness(arch, cals):
    flats = torch.stack([flatten(build(arch, seed=s)) for s in range(4)])
    flats = flats + 0.2 * torch.randn(flats.shape, generator=torch.Generator().manual_seed(0))
    x2, y2 = cals[1][0][:45], cals[1][1][:45]  # a shorter set: padded rows weigh nothing
    stacked = StackedFitness(arch, [cals[0], (x2, y2)], chunk=3)(torch.stack([flats, flats]))
    assert torch.allclose(stacked[0], CalibrationFitness(arch, *cals[0])(flats), rtol=1e-5, atol=1e-6)
    assert torch.allclose(stacked[1], CalibrationFitness(arch, x2, y2)(flats), rtol=1e-5, atol=1e-6)


def _checked(experts, seeds):
    return [checked_inputs(experts, "sn-s", TINY, s, None) for s in seeds]


@pytest.mark.parametrize("phases", [("mmas", "iwoa"), ("mmas",)])
def test_batched_runs_equal_each_run_alone(cals, experts, phases):
    cfg = dataclasses.replace(TINY, phases=phases)
    seeds = [5, 6, 7]
    chk = _checked(experts, seeds)
    together = search_lockstep([c[1] for c in chk], [c[2] for c in chk], StackedFitness("sn-s", cals), cfg, seeds)
    for r, seed in enumerate(seeds):
        alone = search_lockstep([chk[r][1]], [chk[r][2]], StackedFitness("sn-s", [cals[r]]), cfg, [seed])[0]
        assert torch.equal(alone.best_flat, together[r].best_flat)
        assert alone.best_fitness == together[r].best_fitness and alone.history == together[r].history
        assert alone.best_origin == together[r].best_origin
    assert len({res.best_fitness for res in together}) == 3  # three different draws, three results


def test_engine_follows_the_reference_search(cals, experts):
    """Same seed, same uniforms: the engine walks the reference's path, to float rounding."""
    for r, (x, y) in enumerate(cals):
        ref = acomerge(experts, "sn-s", x, y, TINY, seed=r)
        (eng,) = search_lockstep([experts], [checked_inputs(experts, "sn-s", TINY, r, None)[2]],
                                 StackedFitness("sn-s", [(x, y)]), TINY, [r])
        assert eng.best_fitness == pytest.approx(ref.best_fitness, rel=1e-5)
        assert torch.allclose(eng.best_flat, ref.best_flat, atol=1e-6)
        assert eng.best_origin == ref.best_origin
        assert eng.best_fitness <= min(eng.expert_fitness)
        assert all(b <= a for a, b in zip(eng.history["best_so_far"], eng.history["best_so_far"][1:]))
        for key in ("iteration_best", "tau_max", "tau_highest"):
            assert eng.history[key] == pytest.approx(ref.history[key], rel=1e-4)
        assert eng.history["iwoa"] == ref.history["iwoa"] and eng.history["q0"] == ref.history["q0"]


def test_cpu_runs_go_through_the_reference(cals, experts):
    runs = [(experts, x, y, s, None) for s, (x, y) in enumerate(cals[:2])]
    out = run_acomerge_many(runs, "sn-s", TINY)
    for (e, x, y, s, _), res in zip(runs, out):
        assert res.best_fitness == acomerge(e, "sn-s", x, y, TINY, seed=s).best_fitness


@pytest.mark.skipif(not NO_GPU, reason="this machine has a GPU; the refusal is for machines without one")
def test_device_cuda_is_a_one_line_error_without_a_gpu(capsys, tmp_path):
    with pytest.raises(ValueError, match="no CUDA GPU is available"):
        resolve_device("cuda")
    assert resolve_device("auto").type == "cpu"
    with pytest.raises(ValueError, match="device must be"):
        AcoMergeConfig(device="tpu").validate()
    rc = main(["bench", "fusion", "--device", "cuda", "--json"])
    err = capsys.readouterr().err.strip()
    assert rc != 0 and len(err.splitlines()) == 1 and "no CUDA GPU" in err and "Traceback" not in err


# --- a busy machine (issue 30, item 2) ----------------------------------------------------

def test_threads_follow_the_free_cores():
    """With every core taken by a spinning process, a run gets one thread (not a barrier per core)."""
    from fleetlab.compute import busy_cores, default_threads
    from fleetlab.fusion.bench import busy_processes

    cores = os.cpu_count() or 1
    with busy_processes(cores):
        assert busy_cores(0.2) >= cores - 0.5
        assert default_threads() == 1


def test_a_run_takes_no_more_threads_than_the_cores_it_may_use():
    """A process confined to one core (taskset, a container's cpuset, a batch slot) counts one core and
    gives a run one thread, however many the machine has."""
    code = ("import os; os.sched_setaffinity(0, {min(os.sched_getaffinity(0))}); "
            "from fleetlab.compute import default_threads, usable_cores; "
            "print(usable_cores(), default_threads())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["1", "1"]


def test_bench_reports_idle_and_loaded_runs(capsys):
    rc = main(["bench", "fusion", "--json", "--ants", "20", "--generations", "3", "--repeats", "1",
               "--full-runs", "1", "--load", "1"])
    assert rc == 0
    busy = json.loads(capsys.readouterr().out)["busy"]
    assert busy["load"] == 1 and busy["run_s_idle"] > 0 and busy["run_s_loaded"] > 0
    assert busy["run_s_loaded_all_cores"] > 0 and 1 <= busy["threads_loaded"] <= busy["threads_all_cores"]
    # the idle run in two parts: its fitness calls, and what no faster fitness would shorten
    assert 0 < busy["run_s_idle_in_fitness"] < busy["run_s_idle"]
    assert busy["run_s_idle_outside_fitness"] == pytest.approx(busy["run_s_idle"] - busy["run_s_idle_in_fitness"],
                                                               abs=2e-3)
    assert busy["goals"] == {"run_s_idle": 0.35, "run_s_loaded": 0.6,
                             "met": busy["run_s_idle"] <= 0.35 and busy["run_s_loaded"] <= 0.6}


def test_bench_table_needs_the_real_data(capsys):
    """`--table-runs` times the paper table on the target rover's rows: without --data, one line."""
    rc = main(["bench", "fusion", "--json", "--table-runs", "1", "--load", "0"])
    assert rc == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--table-runs needs --data" in err[0]


# --- the whole generation as one CUDA graph, and --rng host (issue 30 follow-up) ----------

def _state(experts, cals, cfg, seeds):
    from fleetlab.fusion.lockstep import _Lockstep, generators

    chk = _checked(experts, seeds)
    ex = torch.stack([c[1] for c in chk])
    cand = torch.stack([c[2] for c in chk])
    return _Lockstep(ex, cand, StackedFitness("sn-s", cals[: len(seeds)]), cfg, generators(seeds, ex.device))


def _tensors(state) -> dict[str, torch.Tensor]:
    out = {k: v for k, v in vars(state).items() if isinstance(v, torch.Tensor)}
    out.update({f"hist.{k}": v for k, v in state.hist.items()})
    return out


@pytest.mark.parametrize("heuristic", ["constant", "best_distance"])
def test_generation_changes_its_state_only_in_place(cals, experts, heuristic):
    """A CUDA graph replays the kernels of one capture on the same addresses: every tensor a
    generation or an IWOA move reads or writes must stay the same tensor, run after run."""
    cfg = dataclasses.replace(TINY, heuristic=heuristic)
    state = _state(experts, cals, cfg, [5, 6])
    before = {k: (v.data_ptr(), v.shape) for k, v in _tensors(state).items()}
    first_tau = state.tau.clone()
    for g in range(cfg.generations):
        state.generation()
        if state.iwoa_flags[g]:
            state.iwoa()
    after = {k: (v.data_ptr(), v.shape) for k, v in _tensors(state).items()}
    assert after == before
    assert int(state.g) == cfg.generations and int(state.c) == sum(state.iwoa_flags) == 3
    assert not torch.equal(state.tau, first_tau) and (state.hist["ants"] != 0).all()


def test_replay_wrapper_steps_the_same_search_as_direct_calls(cals, experts):
    """The loop search_lockstep drives (through _Replayed, eager here) equals calling the steps by
    hand, generation for generation: the graph path adds no step and skips none."""
    from fleetlab.fusion.lockstep import _Replayed

    seeds = [5, 6]
    direct = _state(experts, cals, TINY, seeds)
    wrapped = _state(experts, cals, TINY, seeds)
    gen_step = _Replayed(wrapped.generation, torch.device("cpu"), wrapped.gens, "generation")
    iwoa_step = _Replayed(wrapped.iwoa, torch.device("cpu"), wrapped.gens, "IWOA move")
    assert not gen_step.enabled  # graphs only on CUDA
    for g in range(TINY.generations):
        direct.generation()
        gen_step()
        if direct.iwoa_flags[g]:
            direct.iwoa()
            iwoa_step()
        for name, value in _tensors(direct).items():
            assert torch.equal(value, _tensors(wrapped)[name]), (g, name)


def test_failed_capture_warns_once_and_steps_eagerly(monkeypatch, capsys):
    """Where a capture fails, the step runs eagerly from then on, after one warning line, and the
    generators are where they were before the attempt."""
    from fleetlab.fusion import lockstep

    class NoGraph:
        def __init__(self):
            raise RuntimeError("operation not permitted when stream is capturing\nmore detail")

    monkeypatch.setattr(lockstep.torch.cuda, "CUDAGraph", NoGraph)
    gen = torch.Generator().manual_seed(3)
    drawn = []
    step = lambda: drawn.append(float(torch.rand(1, generator=gen)))  # noqa: E731
    replay = lockstep._Replayed(step, torch.device("cpu"), [gen], "generation", warm=0)
    replay.enabled = True  # as on a GPU
    for _ in range(3):
        replay()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "CUDA graph capture of the AcoMerge generation failed" in err[0]
    assert "operation not permitted" in err[0] and not replay.replaying and not replay.enabled
    reference = torch.Generator().manual_seed(3)
    assert drawn == [float(torch.rand(1, generator=reference)) for _ in range(3)]


def test_host_rng_draws_the_cpu_references_numbers():
    """--rng host: CPU generators whatever the device, seeded as acomerge.search seeds its own."""
    from fleetlab.fusion.lockstep import generators

    host = generators([4, 9], torch.device("cuda"), "host")  # made on the CPU, no GPU needed
    assert all(g.device.type == "cpu" for g in host)
    for g, seed in zip(host, [4, 9]):
        reference = torch.Generator().manual_seed(seed + 1_000_003)
        assert torch.equal(torch.rand(5, generator=g), torch.rand(5, generator=reference))
    with pytest.raises(ValueError, match="rng must be"):
        generators([1], torch.device("cpu"), "gpu")
    with pytest.raises(ValueError, match="rng must be"):
        AcoMergeConfig(rng="gpu").validate()


def test_scheduled_iwoa_coefficients_move_as_the_floats_do():
    """The engine reads a and the inertia from a float32 schedule on the device; the move equals
    the reference's with Python floats, bit for bit."""
    from fleetlab.fusion.acomerge import _schedule, whale_update

    pos = torch.randn(7, 48, 1, generator=torch.Generator().manual_seed(0))
    leader = torch.randint(0, 48, (7,), generator=torch.Generator().manual_seed(1))
    a, w = _schedule(3, 10)
    by_float = whale_update(pos, leader, a, w, 1.0, torch.Generator().manual_seed(2))
    by_tensor = whale_update(pos, leader, torch.tensor(a, dtype=torch.float32), torch.tensor(w, dtype=torch.float32),
                             1.0, torch.Generator().manual_seed(2))
    assert torch.equal(by_float, by_tensor)


def test_rng_option_reaches_the_search_config():
    import argparse

    from fleetlab.cli import evaluate
    from fleetlab.fusion.methods import aco_config

    p = argparse.ArgumentParser()
    evaluate.add_arguments(p)
    settings = evaluate.settings_from_args(p.parse_args(["--data", "unused", "--rng", "host"]))
    assert aco_config(settings.budget).rng == "host"
    assert aco_config(evaluate.settings_from_args(p.parse_args(["--data", "unused"])).budget).rng == "device"


# --- the compiled generation (issue 30: an SN-S generation <= 0.15 ms on one GPU) ------------

def test_compiled_generation_steps_the_same_search(cals, experts):
    """The random-free steps traced by torch.compile (aot_eager here: the same graph capture and
    functionalisation of the in-place state as inductor on a GPU, without a code generator) give the
    plain steps' search: the same ants' paths every generation, the state in the same tensors."""
    from torch._dynamo.utils import counters

    from fleetlab.fusion.lockstep import generation_steps

    cfg = dataclasses.replace(TINY, heuristic="best_distance")
    plain, traced = _state(experts, cals, cfg, [5, 6]), _state(experts, cals, cfg, [5, 6])
    traced.before_draws, traced.after_draws = generation_steps(True, backend="aot_eager")
    assert traced.after_draws is not generation_steps(False)[1]
    before = {k: v.data_ptr() for k, v in _tensors(traced).items()}
    counters.clear()
    for g in range(cfg.generations):
        plain.generation()
        traced.generation()
        if plain.iwoa_flags[g]:
            plain.iwoa()
            traced.iwoa()
        assert torch.equal(plain.best_path, traced.best_path), g
        assert torch.allclose(plain.tau, traced.tau, rtol=1e-5, atol=0), g
        assert torch.allclose(plain.hist["ants"], traced.hist["ants"], rtol=1e-5, atol=0), g
    assert {k: v.data_ptr() for k, v in _tensors(traced).items()} == before
    assert int(traced.g) == cfg.generations
    # each step is one whole graph (nothing left to eager Python between kernels), traced once
    assert not counters["graph_break"] and counters["stats"]["unique_graphs"] == 2, dict(counters)


def test_failed_compilation_warns_once_and_runs_the_plain_steps(cals, experts, capsys):
    """Where compiling fails (no Triton, no C compiler), one warning line, and the generation runs
    the plain steps from then on: the same search as an engine that never tried."""
    from fleetlab.fusion import lockstep

    def broken(state, *args):
        raise RuntimeError("Triton not found\ndetail")

    plain, tried = _state(experts, cals, TINY, [5]), _state(experts, cals, TINY, [5])
    tried.before_draws, tried.after_draws = broken, broken
    for _ in range(3):
        plain.generation()
        tried.generation()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "compiling the AcoMerge generation failed (RuntimeError: Triton not found)" in err[0]
    assert tried.after_draws is lockstep._after_draws
    for name, value in _tensors(plain).items():
        assert torch.equal(value, _tensors(tried)[name]), name


def test_bench_fusion_runs_without_the_can_stack():
    """A GPU image often lacks the CAN packages: `bench fusion` (scripts/gpu_check.sh) must still run,
    and the benchmark that needs them says which package is missing, in one line."""
    import subprocess
    import sys

    code = ("import sys; sys.modules['cantools'] = None; from fleetlab.cli import main; "
            "sys.exit(main(sys.argv[1:]))")
    fusion = subprocess.run([sys.executable, "-c", code, "bench", "fusion", "--help"],
                            capture_output=True, text=True, timeout=120)
    assert fusion.returncode == 0, fusion.stderr
    assert "--device" in fusion.stdout and "--table-runs" in fusion.stdout
    link = subprocess.run([sys.executable, "-c", code, "bench", "link"], capture_output=True, text=True, timeout=120)
    assert link.returncode == 1 and link.stderr.strip().splitlines() == [
        "fleetlab bench: error: benchmark 'link' needs the Python package 'cantools', which is not installed here"]


def test_training_probe_runs_on_the_cpu_and_reports(tmp_path):
    """scripts/gpu_training_probe.py (a gpu_check step: is a training step faster on the GPU?) on a
    machine without a GPU: the CPU ways are timed, gpu_check_report.py prints them, and asking for
    the GPU here is one line."""
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[1]
    probe = [sys.executable, str(root / "scripts/gpu_training_probe.py")]
    done = subprocess.run([*probe, "--devices", "cpu", "--arch", "sn-d", "--batch", "32", "--steps", "3"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    rows = json.loads(done.stdout)["step_ms"]
    assert [(r["arch"], r["batch"]) for r in rows] == [("sn-d", 32)]
    assert rows[0]["cpu-1_ms"] > 0 and "cuda_ms" not in rows[0]
    (tmp_path / "training_probe.json").write_text(done.stdout)
    report = subprocess.run([sys.executable, str(root / "scripts/gpu_check_report.py"), str(tmp_path)],
                            capture_output=True, text=True, timeout=60)
    assert report.returncode == 0 and "sn-d batch  32: cpu-1 " in report.stdout, report.stderr
    if not torch.cuda.is_available():
        gpu = subprocess.run([*probe, "--steps", "1"], capture_output=True, text=True, timeout=120)
        assert gpu.returncode == 2 and gpu.stderr.strip().splitlines() == [
            "gpu_training_probe: torch sees no CUDA GPU here (use --devices cpu)"]
