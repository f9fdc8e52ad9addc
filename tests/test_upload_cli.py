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

from test_canopen_node import EXAMPLE, bdir, new_bundle  # noqa: F401


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
    # initiate + segments + one ack per 127 segments + end, each answered, + the activation's pair
    assert r["sdo_frames"] == 2 + n_seg + -(-n_seg // 127) + 2 + 2
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
