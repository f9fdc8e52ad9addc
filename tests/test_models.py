import numpy as np
import pytest
import torch

from fleetlab.models import batched_logits, build, flatten, load_flat, load_model, n_params, save_model
from fleetlab.models.train import class_weights, predict, train_classifier


def test_parameter_counts():
    assert n_params("sn-s") == 543 and n_params("sn-d") == 12547
    assert sum(p.numel() for p in build("sn-s").parameters()) == 543


@pytest.mark.parametrize("arch", ["sn-s", "sn-d"])
def test_batched_forward_equals_module(arch):
    models = [build(arch, seed=s).eval() for s in range(3)]
    x = torch.randn(40, 12) * 5
    flat = torch.stack([flatten(m) for m in models])
    out = batched_logits(arch, flat, x)
    for m, o in zip(models, out):
        torch.testing.assert_close(o, m(x), atol=2e-5, rtol=1e-5)


def test_flat_roundtrip_and_size_check():
    a, b = build("sn-s", seed=0), build("sn-s", seed=1)
    load_flat(b, flatten(a))
    assert torch.equal(flatten(a), flatten(b))
    with pytest.raises(ValueError, match="542 values"):
        load_flat(b, torch.zeros(542))


def test_class_weights_formula():
    w = class_weights(np.array([0, 0, 0, 0, 1, 1, 2, 2]))
    torch.testing.assert_close(w, torch.tensor([8 / 12, 8 / 6, 8 / 6]))
    assert class_weights(np.array([0, 0, 1]))[2] == 0


def test_training_is_seeded_and_learns():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(300, 12)).astype(np.float32)
    y = (x[:, 0] > 0).astype(int) + (x[:, 1] > 1).astype(int)
    m1 = train_classifier(build("sn-s", seed=0), x, y, epochs=15, seed=5)
    m2 = train_classifier(build("sn-s", seed=0), x, y, epochs=15, seed=5)
    assert torch.equal(flatten(m1), flatten(m2))
    assert (predict(m1, x) == y).mean() > 0.85


def test_save_load_roundtrip_and_refusals(tmp_path):
    m = build("sn-s", seed=0)
    p = save_model(tmp_path / "m.pt", m, {"seed": 0, "note": "x"})
    back, meta = load_model(p)
    assert torch.equal(flatten(back), flatten(m)) and meta["arch"] == "sn-s" and meta["seed"] == 0
    p.write_bytes(p.read_bytes()[:100])
    with pytest.raises(ValueError, match="cannot read model file"):
        load_model(p)
    torch.save({"weights": 1}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="not a fleetlab model file"):
        load_model(tmp_path / "other.pt")


def test_damaged_or_edited_model_files_are_one_line_refusals(tmp_path):
    """Garbage bytes, a missing file, a folder and a fleetlab file with edited fields each give one
    ValueError line naming the file (never torch's multi-line advice to load with weights_only=False)."""
    good = save_model(tmp_path / "m.pt", build("sn-s", seed=0))
    payload = torch.load(good, weights_only=True)
    first = next(iter(payload["state_dict"]))

    def edited(name, change):
        copy = {k: dict(v) if isinstance(v, dict) else v for k, v in payload.items()}
        change(copy)
        torch.save(copy, tmp_path / name)
        return tmp_path / name

    (tmp_path / "garbage.pt").write_bytes(b"\x00\x01 not a checkpoint " * 10)
    (tmp_path / "folder.pt").mkdir()
    cases = {
        tmp_path / "garbage.pt": "not a torch checkpoint",
        tmp_path / "absent.pt": "No such file",
        tmp_path / "folder.pt": "Is a directory",
        edited("no_arch.pt", lambda d: d.pop("arch")): "missing or wrong fields: arch",
        edited("other_arch.pt", lambda d: d.update(arch="sn-q")): "unknown architecture 'sn-q'",
        edited("shape.pt", lambda d: d["state_dict"].update({first: torch.zeros(2)})): "is (2,) where a sn-s has (30, 12)",
        edited("dropped.pt", lambda d: d["state_dict"].pop(first)): f"weights missing: ['{first}']",
        edited("nan.pt", lambda d: d["state_dict"].update({first: torch.full((30, 12), float("nan"))})): "NaN or infinity",
    }
    for path, expected in cases.items():
        with pytest.raises(ValueError) as refused:
            load_model(path)
        text = str(refused.value)
        assert expected in text and text.startswith(str(path)) and "\n" not in text, text


def test_training_batches_are_epoch_permutations_cut_to_the_step_budget():
    """The batch order both step engines (CPU loop, captured GPU steps) share: a fresh permutation
    per epoch, an epoch's last batch shorter, exactly `total` batches."""
    from fleetlab.models.train import _batches

    gen = torch.Generator().manual_seed(0)
    batches = list(_batches(10, 4, 7, gen))
    assert [len(b) for b in batches] == [4, 4, 2, 4, 4, 2, 4]
    for epoch in (batches[0:3], batches[3:6]):
        assert sorted(torch.cat(epoch).tolist()) == list(range(10))
    assert not torch.equal(torch.cat(batches[0:3]), torch.cat(batches[3:6]))


def test_sources_train_on_the_gpu_except_when_following_the_cpu_reference():
    from fleetlab.fusion.pipeline import source_device

    assert source_device("cpu", "device") == "cpu"
    assert source_device("cuda:1", "device") == "cuda:1"
    assert source_device("cuda", "host") == "cpu"  # --rng host: the CPU's sources, bit for bit
