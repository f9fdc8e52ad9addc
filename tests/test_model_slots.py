"""A/B model slots in the real emulator process (slipest_emu --nvm FILE): power loss at every NVM write and
erase of an upload, an activation and a rollback, done by SIGKILL from inside the NVM callback: before the
write, after half a sector (a torn write) or right after it. After each death the emulator is restarted on
the same file; it must serve the old model or the new one, never neither, with every vector of the model it
serves bit-exact.

CI runs every write/erase of an upload + activation with 256-byte sectors in the three modes (>= 50 cut
points), a second-generation upload that overwrites the rollback target, and a rollback; and every write/erase
of an SN-D (77 KB, format-2) upload + activation with 256- and 4,096-byte sectors. FLEETLAB_LONG=1 adds 64- and
128-byte sectors to the SN-S sweep (about 4x the cut points).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest

from fleetlab.export import model_image
from fleetlab.export.bundle import export_bundle, load_bundle
from fleetlab.export.f32_bound import recorded_tolerance
from fleetlab.export.image_layout import patch_header
from fleetlab.export.vectors import draw_inputs
from fleetlab.host_tools.emulator import EMULATOR_TARGET, build, find_artifact
from fleetlab.host_tools.firmware.build import cmake_build

from small_models import quick_model, small_model

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "firmware_c" / "bundles" / "example"
LONG = os.environ.get("FLEETLAB_LONG") == "1"
HASH_RE = re.compile(r"model_hash=([0-9a-f]{8}) (PASS|FAIL)")


@pytest.fixture(scope="module")
def emu() -> Path:
    """The emulator of this tree; FLEETLAB_TEST_EMU names another build (e.g. an older commit's, to see a test fail)."""
    if os.environ.get("FLEETLAB_TEST_EMU"):
        return Path(os.environ["FLEETLAB_TEST_EMU"])
    return find_artifact(build(None, targets=(EMULATOR_TARGET,)), EMULATOR_TARGET)


@pytest.fixture(scope="module")
def models(tmp_path_factory) -> dict:
    """old: the example bundle (version 1, the emulator's built-in model); new: another trained SN-S
    exported as version 2, with its own vectors."""

    out = tmp_path_factory.mktemp("slots") / "new"
    export_bundle(small_model(seed=9), out, inputs=draw_inputs(1000, None, seed=3), model_version=2)
    old, new = load_bundle(EXAMPLE), load_bundle(out)
    assert old.content_hash[:8] != new.content_hash[:8]
    return {"old": (EXAMPLE / "model.img", EXAMPLE / "vectors.bin", old.content_hash[:8]),
            "new": (out / "model.img", out / "vectors.bin", new.content_hash[:8]), "dir": out}


def run(emu: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(emu), *args], capture_output=True, text=True, timeout=60)


def vectors_args(vectors_bin: Path) -> list[str]:
    """--vectors of a bundle with that bundle's float tolerance (manifest.json float_tolerance)."""
    tol = recorded_tolerance(json.loads((vectors_bin.parent / "manifest.json").read_text()))
    return ["--vectors", str(vectors_bin), "--f32-tol", repr(tol)]


def nvm_ops(res: subprocess.CompletedProcess) -> int:
    m = re.search(r"nvm ops=(\d+)", res.stderr)
    assert m, res.stderr
    return int(m.group(1))


def served(emu: Path, nvm: Path, sector: int, models: dict) -> str:
    """Boot the emulator on nvm, find which model it serves and check that model's vectors bit-exact."""
    res = run(emu, "--nvm", str(nvm), "--nvm-sector", str(sector), *vectors_args(models["old"][1]))
    m = HASH_RE.search(res.stdout)
    assert m, res.stdout + res.stderr
    if m.group(1) == models["old"][2]:
        # every vector of the old model (the example bundle's 1,200) bit-exact, as for the new one below
        assert m.group(2) == "PASS" and res.returncode == 0, res.stdout + res.stderr
        assert "q_exact=1200 f32_within_tol=1200" in res.stdout, res.stdout + res.stderr
        return "old"
    assert m.group(1) == models["new"][2], f"served model {m.group(1)} is neither the old nor the new one"
    res = run(emu, "--nvm", str(nvm), "--nvm-sector", str(sector), *vectors_args(models["new"][1]))
    assert res.returncode == 0 and "q_exact=1000 f32_within_tol=1000" in res.stdout and "PASS" in res.stdout, \
        res.stdout + res.stderr
    return "new"


def cut_sweep(emu: Path, base: Path, work: Path, sector: int, models: dict, op_args: list[str]) -> list[str]:
    """For every NVM write/erase K of `op_args` on a copy of base, in every cut mode: die at K, reboot,
    check. Returns the model served after each cut, in order (K ascending, modes before, torn, after)."""
    shutil.copyfile(base, work)
    full = run(emu, "--nvm", str(work), "--nvm-sector", str(sector), *op_args)
    assert full.returncode == 0, full.stderr
    n_ops = nvm_ops(full)
    outcomes = []
    for k in range(1, n_ops + 1):
        for mode in ("before", "torn", "after"):
            shutil.copyfile(base, work)
            res = run(emu, "--nvm", str(work), "--nvm-sector", str(sector), *op_args, "--nvm-cut-after", str(k),
                      "--nvm-cut-mode", mode)
            assert res.returncode == -signal.SIGKILL, f"cut {k} {mode}: not killed ({res.returncode})"
            outcomes.append(served(emu, work, sector, models))
    return outcomes


def make_base(emu: Path, path: Path, sector: int, models: dict) -> None:
    """An NVM file whose active slot holds the old model (uploaded and activated, no cut)."""
    path.unlink(missing_ok=True)
    res = run(emu, "--nvm", str(path), "--nvm-sector", str(sector), "--upload", str(models["old"][0]), "--activate")
    assert res.returncode == 0 and "activated: slot 0" in res.stderr, res.stderr


def check_switch(outcomes: list[str], first: str, then: str, what: str) -> None:
    """`first` for every cut before the last op (the program of the commit record), then `then` from some
    mode of that last op on: before it, old; after it, new; torn, whichever the half sector holds (a
    record cut short fails its CRC; one wholly in the first half is complete)."""
    j = outcomes.index(then) if then in outcomes else len(outcomes)
    assert outcomes == [first] * j + [then] * (len(outcomes) - j), f"{what}: {outcomes}"
    assert len(outcomes) - 3 < j < len(outcomes), f"{what}: switched at cut {j} of {len(outcomes)}"


@pytest.mark.parametrize("sector", [256] + ([64, 128] if LONG else []))
def test_power_loss_during_upload_and_activation(emu, models, tmp_path, sector) -> None:
    base, work = tmp_path / "base.nvm", tmp_path / "work.nvm"
    make_base(emu, base, sector, models)
    t0 = time.monotonic()
    outcomes = cut_sweep(emu, base, work, sector, models, ["--upload", str(models["new"][0]), "--activate"])
    elapsed = time.monotonic() - t0
    print(f"sector {sector}: {len(outcomes)} cut points in {elapsed:.1f} s: "
          f"{outcomes.count('old')} old, {outcomes.count('new')} new")
    assert len(outcomes) >= 50
    check_switch(outcomes, "old", "new", f"upload+activate, sector {sector}")


@pytest.fixture(scope="module")
def table_emu() -> Path:
    """The emulator of a node that takes format-2 (layer-table) images: built with the layer-table reader, and
    with 4,096-byte NVM sectors (SLIPEST_STORE_SECTOR_MAX) for the SN-D sweep below."""
    opts = {"SLIPEST_LAYER_TABLE": "ON", "SLIPEST_STORE_SECTOR_MAX": "4096"}
    return find_artifact(build(None, targets=(EMULATOR_TARGET,), options=opts), EMULATOR_TARGET)


@pytest.fixture(scope="module")
def snd_models(tmp_path_factory) -> dict:
    """old: the example SN-S (version 1); new: an SN-D exported as version 2 (a 77 KB format-2 image)."""

    out = tmp_path_factory.mktemp("slots-snd") / "new"
    export_bundle(quick_model("sn-d"), out, inputs=draw_inputs(1000, None, seed=3), model_version=2)
    old, new = load_bundle(EXAMPLE), load_bundle(out)
    assert (out / "model.img").read_bytes()[4] == 2 and (out / "model.img").stat().st_size > 70000
    return {"old": (EXAMPLE / "model.img", EXAMPLE / "vectors.bin", old.content_hash[:8]),
            "new": (out / "model.img", out / "vectors.bin", new.content_hash[:8]), "dir": out}


# Every write and erase at the store's default 256-byte sectors: an SN-D slot is 302 sectors, the upload +
# activation about 620 NVM operations, 1,860 cut points (about 15 s on one core: no sampling, no larger
# sector needed), and once more with 4,096-byte sectors (19 a slot), a build that raised SLIPEST_STORE_SECTOR_MAX.
@pytest.mark.parametrize("sector", [256, 4096])
def test_power_loss_during_an_sn_d_upload_and_activation(table_emu, snd_models, tmp_path, sector) -> None:
    """The sweep above over an SN-D (format-2) upload that replaces an active SN-S: every write and erase, in
    the three cut modes, leaves the SN-S or the SN-D serving, each bit-exact on its own vectors."""
    base, work = tmp_path / "base.bin", tmp_path / "work.bin"
    make_base(table_emu, base, sector, snd_models)
    t0 = time.monotonic()
    outcomes = cut_sweep(table_emu, base, work, sector, snd_models,
                         ["--upload", str(snd_models["new"][0]), "--activate"])
    print(f"SN-D, sector {sector}: {len(outcomes)} cut points in {time.monotonic() - t0:.1f} s")
    assert len(outcomes) >= 3 * 2 * ((snd_models["new"][0].stat().st_size + sector - 1) // sector)
    check_switch(outcomes, "old", "new", f"SN-D upload+activate, sector {sector}")


def test_c_store_takes_a_format_2_image(snd_models) -> None:
    """firmware_c/tests/test_store_table.c, built by CMake with the SN-D bundle (so with the layer-table reader):
    the store's streaming validator loads the very model slipest_image_read_table() reads, boots it again, and
    refuses edited images (CRC, row bound, LayerNorm bias, NaN, shift, table size, stale version)."""
    exe = find_artifact(build(snd_models["dir"], targets=("test_store_table",)), "test_store_table")
    res = subprocess.run([str(exe), str(snd_models["new"][0])], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0 and "all checks passed" in res.stdout, res.stdout + res.stderr


def test_power_loss_during_rollback(emu, models, tmp_path) -> None:
    sector = 256
    base, work = tmp_path / "base.nvm", tmp_path / "work.nvm"
    make_base(emu, base, sector, models)
    res = run(emu, "--nvm", str(base), "--upload", str(models["new"][0]), "--activate")
    assert res.returncode == 0 and "activated: slot 1" in res.stderr, res.stderr
    # the base now serves "new" with "old" as the rollback target: a cut rollback serves one of the two
    outcomes = cut_sweep(emu, base, work, sector, models, ["--rollback"])
    assert len(outcomes) == 6  # erase and program of one record sector, three modes each
    check_switch(outcomes, "new", "old", "rollback")


@pytest.mark.parametrize("sector", [256] + ([64] if LONG else []))
def test_power_loss_when_the_upload_overwrites_the_rollback_target(emu, models, tmp_path, sector) -> None:
    """Old (v1) in slot 0, new (v2) active in slot 1; the old model again as version 3 goes into slot 0,
    erasing the rollback target. Every cut leaves v2 or v3 active, never neither."""
    base, work = tmp_path / "base.nvm", tmp_path / "work.nvm"
    make_base(emu, base, sector, models)
    assert run(emu, "--nvm", str(base), "--nvm-sector", str(sector), "--upload", str(models["new"][0]),
               "--activate").returncode == 0
    b = load_bundle(EXAMPLE)
    v3 = tmp_path / "v3.img"
    v3.write_bytes(model_image.image_bytes(b.qparams, b.fparams, b.content_hash, model_version=3))
    outcomes = cut_sweep(emu, base, work, sector, models, ["--upload", str(v3), "--activate"])
    assert len(outcomes) >= 50
    # v3 has the old model's parameters (and hash): "old" here means v3 is served
    check_switch(outcomes, "new", "old", "second-generation upload")


# ----------------------------------------------------------------------- trial activation (issue 45 item 2)
# An activation on trial (the CiA 302-3 "start", slipest_store_try()) writes one commit record marked "trial"; a
# confirm (0x1F51 = 0x80, slipest_store_confirm()) one more without the mark; a boot that finds the mark reverts to
# the previous model with one record (slipest_store_open()). Each of those NVM operations is cut in the three modes.

def test_power_loss_during_upload_and_trial_activation(emu, models, tmp_path) -> None:
    """Every cut of an upload + activation on trial leaves the old model serving after the reboot: before the trial
    record it was never replaced, after it the boot reverts the unconfirmed model."""
    sector = 256
    base, work = tmp_path / "base.nvm", tmp_path / "work.nvm"
    make_base(emu, base, sector, models)
    outcomes = cut_sweep(emu, base, work, sector, models, ["--upload", str(models["new"][0]), "--try"])
    assert len(outcomes) >= 50 and outcomes == ["old"] * len(outcomes), outcomes
    # no cut: on trial until the process ends; the next boot reverts it, says so, and writes the revert once
    shutil.copyfile(base, work)
    res = run(emu, "--nvm", str(work), "--upload", str(models["new"][0]), "--try")
    assert res.returncode == 0 and "on trial: slot 1" in res.stderr, res.stderr
    res = run(emu, "--nvm", str(work))
    assert "version 1, trial reverted" in res.stderr and nvm_ops(res) == 2, res.stderr
    res = run(emu, "--nvm", str(work))
    assert "trial" not in res.stderr and nvm_ops(res) == 0, res.stderr


def test_power_loss_during_trial_and_confirm(emu, models, tmp_path) -> None:
    """Upload, activation on trial and its confirm in one run: every cut before the confirm's record program leaves
    the old model (the trial reverted at the reboot), a cut after it the new one, confirmed (no revert at the
    reboot)."""
    sector = 256
    base, work = tmp_path / "base.nvm", tmp_path / "work.nvm"
    make_base(emu, base, sector, models)
    outcomes = cut_sweep(emu, base, work, sector, models,
                         ["--upload", str(models["new"][0]), "--try", "--confirm"])
    check_switch(outcomes, "old", "new", "trial + confirm")
    shutil.copyfile(base, work)
    assert run(emu, "--nvm", str(work), "--upload", str(models["new"][0]), "--try", "--confirm").returncode == 0
    res = run(emu, "--nvm", str(work))
    assert "version 2" in res.stderr and "trial" not in res.stderr and nvm_ops(res) == 0, res.stderr


def test_power_loss_during_the_revert_of_a_trial(emu, models, tmp_path) -> None:
    """The NVM holds a model on trial; the boot reverts it (erase and program of one record sector). A cut in any
    mode of either leaves the old model serving after the next boot, which finishes the revert."""
    sector = 256
    base, work = tmp_path / "base.nvm", tmp_path / "work.nvm"
    make_base(emu, base, sector, models)
    res = run(emu, "--nvm", str(base), "--upload", str(models["new"][0]), "--try")
    assert res.returncode == 0 and "on trial" in res.stderr, res.stderr
    outcomes = cut_sweep(emu, base, work, sector, models, [])
    assert outcomes == ["old"] * 6, outcomes  # two operations, three modes each
    res = run(emu, "--nvm", str(work))
    assert "version 1" in res.stderr and "trial" not in res.stderr and nvm_ops(res) == 0, res.stderr


def test_refused_uploads_keep_the_old_model(emu, models, tmp_path) -> None:
    """Corrupt, truncated, older and wrong-architecture images are refused by the emulator's store with
    their reason; the active model and its vectors are unchanged."""
    nvm = tmp_path / "n.nvm"
    make_base(emu, nvm, 256, models)
    good = models["new"][0].read_bytes()
    cases = {
        "flip": (good[:300] + bytes([good[300] ^ 1]) + good[301:], "CRC mismatch"),
        "truncated": (good[:-5], "wrong length"),
        "arch": (patch_header(good, arch=2), "model architecture mismatch"),
        "older": ((EXAMPLE / "model.img").read_bytes(), "model version not newer than the active one"),
    }
    for name, (data, why) in cases.items():
        img = tmp_path / f"{name}.img"
        img.write_bytes(data)
        res = run(emu, "--nvm", str(nvm), "--upload", str(img), "--activate")
        assert res.returncode == 3 and f"upload refused: {why}" in res.stderr, (name, res.stderr)
        assert served(emu, nvm, 256, models) == "old"


@pytest.fixture(scope="module")
def keyed_emu(tmp_path_factory) -> tuple[Path, bytes]:
    """An emulator built with -DSLIPEST_HMAC_KEY_FILE (the key provisioned at build time)."""
    root = tmp_path_factory.mktemp("keyed")
    key = bytes(range(100, 132))
    (root / "key.bin").write_bytes(key)
    bdir = cmake_build(root / "build", EXAMPLE, options={"SLIPEST_HMAC_KEY_FILE": str(root / "key.bin")},
                       jobs=2, targets=(EMULATOR_TARGET,))
    return find_artifact(bdir, EMULATOR_TARGET), key


def test_hmac_provisioned_build_refuses_unsigned_and_wrongly_signed_images(keyed_emu, models, tmp_path) -> None:
    emu_k, key = keyed_emu
    nvm = tmp_path / "k.nvm"
    new = models["new"][0].read_bytes()
    for name, data in {"unsigned": new, "wrong key": model_image.sign_image(new, bytes(32))}.items():
        img = tmp_path / "x.img"
        img.write_bytes(data)
        res = run(emu_k, "--nvm", str(nvm), "--upload", str(img), "--activate")
        assert res.returncode == 3 and "upload refused: model image authentication failed" in res.stderr, \
            (name, res.stderr)
        assert "store boot: built-in model" in res.stderr  # still the built-in (old) model
    # the image `fleetlab export --hmac-key` writes (export_bundle(hmac_key=...)) is accepted

    from fleetlab.export.bundle import check_bundle

    signed = tmp_path / "signed_bundle"
    export_bundle(small_model(seed=9), signed, inputs=draw_inputs(1000, None, seed=3), model_version=2, hmac_key=key)
    check_bundle(signed)
    img = signed / "model.img"
    assert model_image.read_image(img.read_bytes(), hmac_key=key).content_hash[:8] == models["new"][2]
    res = run(emu_k, "--nvm", str(nvm), "--upload", str(img), "--activate")
    assert res.returncode == 0 and "activated: slot 0" in res.stderr, res.stderr
    res = run(emu_k, "--nvm", str(nvm), *vectors_args(models["new"][1]))
    assert res.returncode == 0 and f"model_hash={models['new'][2]} PASS" in res.stdout, res.stdout + res.stderr
