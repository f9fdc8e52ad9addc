"""`fleetlab upload` end to end against the emulator (`--emulate`): over CAN (slcan) and over the
serial link (the same CAN frames in COBS packets), with activation and read-back, and clear
errors for a refused image or a folder without model.img."""

from __future__ import annotations

import json
import shutil

import pytest

from fleetlab.canopen_od import objects as od
from fleetlab.cli import main
from fleetlab.export.bundle import load_bundle
from fleetlab.host_tools.verify.upload_faults import faulty_image

from canopen_helpers import EXAMPLE
from small_models import quick_model


@pytest.mark.parametrize("link", ["canopen", "serial"])
def test_upload_activates_and_reads_back(bdir, new_bundle, tmp_path, capsys, link):
    nvm = tmp_path / "nvm.bin"
    assert main(["upload", "--bundle", str(new_bundle), "--link", link, "--emulate", "--nvm", str(nvm),
                 "--activate", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    new = load_bundle(new_bundle)
    assert r["before"] == {"version": 1, "hash32": "4e583ed2"}
    assert r["active_version"] == 2 and r["active_sha256"] == new.content_hash and r["activated"]
    n_seg = -(-r["image_bytes"] // 7)
    # CiA 302-3: the clear, then initiate + segments + one ack per 127 segments + end, each answered, then the
    # start and the confirm, each a request and its answer
    assert r["sdo_frames"] == 2 + 2 + n_seg + -(-n_seg // 127) + 2 + 2 + 2
    assert 0.1 < r["bus_time_s_at_500k"] < 0.2
    # the NVM file keeps the model: a second run finds version 2 active and refuses a re-upload of it
    assert main(["upload", "--bundle", str(new_bundle), "--link", link, "--emulate", "--nvm", str(nvm)]) == 1
    err = capsys.readouterr().err
    assert f"SDO abort 0x{od.ABORT['STORE']:08X}" in err and "image refused" in err


def test_upload_errors_are_one_clear_line(bdir, new_bundle, tmp_path, capsys):
    assert main(["upload", "--bundle", str(tmp_path), "--emulate"]) == 1
    assert "no model.img" in capsys.readouterr().err
    bad = tmp_path / "bad"
    shutil.copytree(new_bundle, bad)
    (bad / "model.img").write_bytes(faulty_image("wrong_arch", (new_bundle / "model.img").read_bytes()))
    assert main(["upload", "--bundle", str(bad), "--emulate", "--activate"]) == 1
    assert f"SDO abort 0x{od.ABORT['STORE']:08X}" in capsys.readouterr().err
    assert main(["upload", "--bundle", str(new_bundle)]) == 1
    assert "--channel" in capsys.readouterr().err


def test_rehearsal_streams_through_the_upload_and_switches_bit_exact(bdir, new_bundle, tmp_path, capsys):
    """--rehearse: windows stream during the upload (all answered by the boot model, bit-exact), the image is
    activated between two windows, and the next windows equal the new model's torch integer reference."""
    report = tmp_path / "landing.json"
    assert main(["upload", "--bundle", str(new_bundle), "--emulate", "--boot-bundle", str(EXAMPLE),
                 "--rehearse", "6", "--scale", "0.1", "--report", str(report)]) == 0
    r = json.loads(report.read_text())
    assert r["boot_model_bit_exact"] and r["new_model_bit_exact"]
    assert r["windows_answered_during_upload_phase"] == r["windows_streamed_during_upload_phase"] == 6
    assert r["before"]["version"] == 1 and r["after"]["version"] == 2 and r["windows_after_activation"] == 6
    assert "bit-exact with the new model: True" in capsys.readouterr().out


@pytest.fixture(scope="module")
def snd_bundle(tmp_path_factory):
    """An SN-D (12 -> 128 -> 64 -> 32 -> 3) exported as model version 2: a 77 KB format-2 image."""
    from fleetlab.export.bundle import export_bundle
    from fleetlab.export.vectors import draw_inputs

    out = tmp_path_factory.mktemp("upload-snd") / "snd"
    export_bundle(quick_model("sn-d"), out, inputs=draw_inputs(200, None, seed=3), model_version=2)
    return out


@pytest.mark.parametrize("link", ["canopen", "serial"])
def test_sn_d_image_uploads_activates_and_serves_bit_exact(snd_bundle, tmp_path, capsys, link):
    """An SN-D image through the emulated node's CANopen DOMAIN (slcan, or the serial link's COBS packets):
    uploaded into the store, validated, activated; windows streamed before the upload are answered bit-exact by
    the boot SN-S and those after the activation bit-exact by the SN-D (its torch integer reference). The
    report gives the SDO frames and the bus time at 500 kbit/s, computed from them."""
    report = tmp_path / "landing.json"
    assert main(["upload", "--bundle", str(snd_bundle), "--link", link, "--emulate", "--boot-bundle", str(EXAMPLE),
                 "--rehearse", "4", "--scale", "0.1", "--report", str(report)]) == 0
    r = json.loads(report.read_text())
    assert r["boot_model_bit_exact"] and r["new_model_bit_exact"], r
    assert r["before"]["version"] == 1 and r["after"]["version"] == 2
    assert r["after"]["hash32"] == load_bundle(snd_bundle).content_hash[:8]
    up = r["upload"]
    assert up["image_bytes"] == (snd_bundle / "model.img").stat().st_size > 70000
    n_seg = -(-up["image_bytes"] // 7)
    assert up["sdo_frames"] >= 2 + n_seg + -(-n_seg // 127)  # block download: every segment on the bus
    assert 2.0 < up["bus_time_s_at_500k"] < 3.5  # about 1.3 Mbit: SN-S's 0.15 s times the image's 20x
    out = capsys.readouterr().out
    assert "ms at 500 kbit/s" in out and "bit-exact with the new model: True" in out


def test_sn_d_image_is_refused_by_an_sn_s_only_node(snd_bundle, tmp_path):
    """A node built without the layer-table reader (the SN-S library) keeps its slot at the format-1 size and
    refuses the SN-D image by its announced length (SDO abort 0x06070012), with one clear line."""
    from fleetlab.host_tools.canopen_session import CanopenSession, eds_for
    from fleetlab.host_tools.emulator import EMULATOR_TARGET, build, find_artifact
    from fleetlab.host_tools.upload import explain, open_tapped, upload_image

    bdir = build(None, targets=(EMULATOR_TARGET,))
    session, tap = open_tapped("slcan", eds_for(bdir), 5, emulator=find_artifact(bdir, EMULATOR_TARGET),
                               nvm_file=tmp_path / "nvm.bin")
    assert isinstance(session, CanopenSession)
    with session, pytest.raises(Exception) as e:
        upload_image(session, tap, (snd_bundle / "model.img").read_bytes(), activate=True)
    assert "0x06070012" in explain(e.value)


def test_upload_no_confirm_leaves_a_trial_that_the_next_boot_reverts(bdir, new_bundle, tmp_path, capsys):
    """--activate --no-confirm: the new model runs on trial (CiA 302-3 start without the 0x80 confirm); the next
    emulator process on the same NVM file boots the previous model. Without --no-confirm it stays."""
    nvm = tmp_path / "nvm.bin"
    assert main(["upload", "--bundle", str(new_bundle), "--emulate", "--nvm", str(nvm), "--activate", "--no-confirm",
                 "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["active_version"] == 2 and r["activated"] and not r["confirmed"]
    assert main(["upload", "--rollback", "--emulate", "--nvm", str(nvm), "--json"]) == 1  # reverted: nothing to roll to
    capsys.readouterr()
    assert main(["upload", "--bundle", str(new_bundle), "--emulate", "--nvm", str(nvm), "--activate", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["before"]["version"] == 1 and r["active_version"] == 2 and r["confirmed"]
    assert main(["upload", "--bundle", str(new_bundle), "--emulate", "--nvm", str(nvm)]) == 1  # v2 stayed: stale
    assert "stale version" in capsys.readouterr().err
    assert main(["upload", "--no-confirm", "--bundle", str(new_bundle), "--emulate"]) == 1
    assert "--no-confirm needs --activate" in capsys.readouterr().err
