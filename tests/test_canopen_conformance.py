"""Issue 45, "CANopen by the book": the node and its EDS checked against CiA 301 / CiA 306 from outside the
project.

- The generated EDS passes an independent validator (`eds-validate`, PyPI eds-utils) and python `canopen`'s own
  parser finds every object of canopen_od/objects.py in it; its [FileInfo] dates are the dictionary's own, not
  the clock's (the generator stays byte-reproducible).
- Every object the EDS lists as readable answers a read in every state the node can boot into: its built-in
  model, no model at all (a flight image), an uploaded model, after a power cycle, without a store, with the
  built-in model taken from an image.
- CiA 301 store / restore (0x1010 / 0x1011 sub 1, signatures "save" / "load"): what 0x1010 stores survives a
  real restart of slipest_emu on the same NVM file, a power cut inside the store's NVM writes leaves the old or
  the new parameters, 0x1011 brings the defaults back after a reset; python `canopen` is the master, over slcan.
- Refusals say why: `fleetlab upload` prints the node's reason, and a rollback after a refused image took the
  rollback target's slot says "no previous model" in one line (`fleetlab upload --rollback`).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import can
import canopen
import pytest

from fleetlab.canopen_od import generate
from fleetlab.canopen_od import objects as od
from fleetlab.cli import main
from fleetlab.export import image_layout
from fleetlab.export.bundle import load_bundle
from fleetlab.host_tools.canopen_session import CanopenSession, eds_for
from fleetlab.host_tools.emulator import EMULATOR_TARGET, find_artifact
from fleetlab.host_tools.verify.upload_faults import faulty_image

from canopen_helpers import EXAMPLE, NODE_ID
from required import need_module

ZERO_SHA = "00" * 32


# ------------------------------------------------------------------------------------------------ the EDS
def eds_validate(path: Path) -> subprocess.CompletedProcess:
    """Run eds-utils' `eds-validate` on `path` (the command beside this Python, else its entry point)."""
    need_module("eds_utils.eds_validate", "eds-utils")
    script = Path(sys.executable).with_name("eds-validate")
    cmd = [str(script)] if script.is_file() else \
        [sys.executable, "-c", "import sys; from eds_utils.eds_validate import eds_validate; eds_validate()"]
    return subprocess.run([*cmd, str(path)], capture_output=True, text=True, timeout=120)


def test_generated_eds_passes_eds_validate(bdir, tmp_path):
    """The EDS the build generates and the one `fleetlab upload` writes for a real bus: no finding at all (the
    validator prints each on stderr and exits 1; before issue 45 the [FileInfo] modification fields were missing)."""
    own = tmp_path / "slipest.eds"
    own.write_text(generate.eds_text())
    assert own.read_bytes() == eds_for(bdir).read_bytes()
    for path in (eds_for(bdir), own):
        res = eds_validate(path)
        assert res.returncode == 0 and res.stderr == "" and res.stdout == "", (path, res.stderr, res.stdout)


def test_eds_validate_catches_what_it_is_run_for(tmp_path):
    """Negative control: the same EDS without its ModificationDate / ModifiedBy is a finding."""
    text = "\n".join(line for line in generate.eds_text().split("\n")
                     if not line.startswith(("ModificationDate=", "ModifiedBy=")))
    bad = tmp_path / "bad.eds"
    bad.write_text(text)
    res = eds_validate(bad)
    assert res.returncode == 1 and "ModifiedBy was missing" in res.stderr


def test_generator_refuses_a_mapping_the_node_would_compute_otherwise():
    """A PDO mapping entry's EDS value must be what the C node computes from the mapped sub-index (OD kind "map")."""
    ents = od.objects()
    generate._check_mappings(ents)  # the real dictionary agrees
    entry = next(e for e in ents if e.kind == "map")
    entry.default ^= 0x08  # another bit length than the mapped value's
    with pytest.raises(ValueError, match="is not what the node computes"):
        generate._check_mappings(ents)


def test_eds_file_info_is_the_object_dictionarys_not_the_clocks():
    """FileVersion/FileRevision are the dictionary's version and the dates are fixed in objects.py: the EDS is the
    same bytes whenever it is generated (tests/test_determinism.py compares them across machines too)."""
    text = generate.eds_text()
    assert text == generate.eds_text()
    info = dict(line.split("=", 1) for line in text.split("\n\n", 1)[0].split("\n")[1:])
    assert (int(info["FileVersion"]), int(info["FileRevision"])) == od.OD_VERSION
    assert (info["CreationDate"], info["CreationTime"]) == od.OD_CREATED
    assert (info["ModificationDate"], info["ModificationTime"]) == od.OD_VERSION_DATE
    assert info["ModifiedBy"] and info["CreatedBy"]


def test_canopen_import_od_finds_every_object(bdir):
    """python canopen's parser reads the build's EDS and finds every (index, sub) of the source, each with its
    data type and access, and nothing else."""
    od_py = canopen.import_od(str(eds_for(bdir)), NODE_ID)
    want = {(e.index, e.sub): e for e in od.objects()}
    found = {}
    for obj in od_py.values():
        if isinstance(obj, canopen.objectdictionary.ODVariable):
            found[(obj.index, 0)] = obj
        else:
            for sub in obj.values():
                found[(obj.index, sub.subindex)] = sub
    assert sorted(found) == sorted(want)
    for key, e in want.items():
        assert found[key].data_type == e.dtype and found[key].access_type == e.access, key
    assert od_py[od.IDX_STORE_PARAMS][1].default == 1 and od_py[od.IDX_RESTORE_PARAMS][1].default == 1


# ----------------------------------------------------------------------------- readable in every boot state
def readable_entries() -> list:
    return [e for e in od.objects() if e.access in ("const", "ro", "rw", "rww", "rwr")]


def read_everything(session: CanopenSession) -> dict[tuple[int, int], bytes]:
    """Every readable object of the EDS by SDO upload; an abort fails the test naming the object."""
    values = {}
    for e in readable_entries():
        try:
            values[(e.index, e.sub)] = session.master.node.sdo.upload(e.index, e.sub)
        except canopen.SdoAbortedError as err:
            meaning = {code: doc for _, code, doc in od.ABORT_CODES}.get(err.code, "?")
            pytest.fail(f"0x{e.index:04X} sub {e.sub} ({e.parent + ': ' if e.parent else ''}{e.name}) aborts "
                        f"0x{err.code:08X} ({meaning})")
        if e.dtype != od.DOMAIN:  # a DOMAIN's length is its content's (0x1F50: the active slot's image, or empty)
            assert len(values[(e.index, e.sub)]) == od.TYPE_BYTES[e.dtype], (hex(e.index), e.sub)
    return values


BOOT_STATES = ("built-in model", "no model (flight image)", "uploaded model", "uploaded model after a power cycle",
               "no store (emulator without --nvm)", "built-in model from an image (emulator --model)")


@pytest.mark.parametrize("state", BOOT_STATES)
def test_every_readable_object_answers_in_every_boot_state(bdir, tmp_path, new_bundle, state):
    lib, emu = find_artifact(bdir, "libslipest_host.so"), find_artifact(bdir, EMULATOR_TARGET)
    example, new = load_bundle(EXAMPLE), load_bundle(new_bundle)
    if state.startswith("no store"):
        session = CanopenSession("slcan", eds_for(bdir), NODE_ID, emulator=emu)
    elif state.startswith("built-in model from an image"):
        session = CanopenSession("slcan", eds_for(bdir), NODE_ID, emulator=emu, nvm_file=tmp_path / "nvm.bin",
                                 builtin_image=new_bundle / "model.img")
    else:
        flight = {"builtin_model": False} if state.startswith("no model") else {}
        session = CanopenSession("inproc", eds_for(bdir), NODE_ID, lib=lib, **flight)
    with session:
        if state.startswith("uploaded"):
            session.master.upload((new_bundle / "model.img").read_bytes())
            session.master.activate()
            if state.endswith("power cycle"):
                session.power_cycle()
        values = read_everything(session)
    # every constant and every PDO mapping entry (which the node computes from the mapped sub-index) reads as the EDS
    # says: its DefaultValue, with the node id added where the EDS adds $NODEID
    for e in od.objects():
        if e.kind in ("const", "map"):
            want = e.default if isinstance(e.default, int) else NODE_ID + int(e.default.removeprefix("$NODEID+"), 0)
            assert values[(e.index, e.sub)] == want.to_bytes(od.TYPE_BYTES[e.dtype], "little"), (hex(e.index), e.sub)
    sha = values[(od.IDX_ACTIVE_MODEL, 3)].hex()
    version = int.from_bytes(values[(od.IDX_ACTIVE_MODEL, 1)], "little")
    expected = {"built-in model": example, "no store (emulator without --nvm)": example, "no model (flight image)": None}
    want = expected.get(state, new)
    assert sha == (want.content_hash if want is not None else ZERO_SHA), state
    assert version == (want.manifest["model_version"] if want is not None else 0)
    # the sha256 and hash32 are one hash: hash32 is its first 4 bytes, big-endian; 0x1F56 (CiA 302-3) is hash32 too
    assert int.from_bytes(values[(od.IDX_ACTIVE_MODEL, 2)], "little") == int(sha[:8], 16)
    assert values[(od.IDX_PROGRAM_SWID, 1)] == values[(od.IDX_ACTIVE_MODEL, 2)]
    # 0x1F50 reads the active slot's image, empty while no slot model runs
    image = (new_bundle / "model.img").read_bytes() if state.startswith("uploaded") else b""
    assert values[(od.IDX_PROGRAM_DATA, 1)] == image, state
    if state.startswith("no store"):  # no slots: both empty, every store counter 0; storing is not offered
        assert all(values[(od.IDX_SLOTS, k)] == bytes(od.TYPE_BYTES[t])
                   for k, (_, t) in enumerate(od.SLOT_FIELDS * 2, start=1))
        assert values[(od.IDX_STORE_PARAMS, 1)] == bytes(4)


# --------------------------------------------------------------------------------- CiA 301 store / restore
def emulator_session(bdir: Path, nvm: Path, *args: str) -> CanopenSession:
    return CanopenSession("slcan", eds_for(bdir), NODE_ID, emulator=find_artifact(bdir, EMULATOR_TARGET),
                          nvm_file=nvm, emulator_args=args)


def heartbeat_time(session: CanopenSession) -> int:
    return session.master.node.sdo[0x1017].raw


# the node's process dies on purpose: python-can's reader thread then finds its pty gone
DIES = pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")


@DIES
def test_store_survives_a_restart_and_restore_brings_the_defaults_back(bdir, tmp_path):
    nvm = tmp_path / "nvm.bin"
    with emulator_session(bdir, nvm) as s:
        node = s.master.node
        assert node.sdo[od.IDX_STORE_PARAMS][1].raw == 1 and node.sdo[od.IDX_RESTORE_PARAMS][1].raw == 1
        assert heartbeat_time(s) == od.HEARTBEAT_MS
        node.sdo[0x1017].raw = 50
        for index, wrong in ((od.IDX_STORE_PARAMS, od.SIGNATURE_LOAD), (od.IDX_STORE_PARAMS, 0x12345678),
                             (od.IDX_RESTORE_PARAMS, od.SIGNATURE_SAVE)):
            with pytest.raises(canopen.SdoAbortedError) as e:
                node.sdo[index][1].raw = wrong
            assert e.value.code == od.ABORT["STORE"] == 0x08000020
        s.master.store_parameters()
        node.sdo[0x1017].raw = 70  # changed after the save: not stored
    with emulator_session(bdir, nvm) as s:  # a new process on the same NVM file
        assert heartbeat_time(s) == 50
        s.proc.kill()  # a power loss, this time
    with emulator_session(bdir, nvm) as s:
        assert heartbeat_time(s) == 50
        s.reset_node()
        assert heartbeat_time(s) == 50  # NMT reset node: the stored value again
        s.master.restore_defaults()
        assert heartbeat_time(s) == 50  # in force only after a reset
        s.reset_node()
        assert heartbeat_time(s) == od.HEARTBEAT_MS
    with emulator_session(bdir, nvm) as s:
        assert heartbeat_time(s) == od.HEARTBEAT_MS


def test_stored_heartbeat_time_is_the_one_the_node_keeps_after_a_power_cycle(bdir):
    """The stored value is the one in force, not only the one read back: after a power cycle the node sends its
    heartbeats every 50 ms of its own millisecond tick (a simulated clock given to slipest_co_tick, no wall time),
    20 in a second instead of the default's one."""
    from fleetlab.host_tools.canopen_node import CCanopenNode, RamNvm, now_ms, nvm_sectors
    from fleetlab.host_tools.wire.dbc import Frame

    lib = find_artifact(bdir, "libslipest_host.so")
    node = CCanopenNode(lib, NODE_ID, nvm=RamNvm(nvm_sectors(lib)))
    t0 = now_ms() + 2**31  # half the 32-bit tick away from boot: surely past a period (the node counts modulo 2^32)

    def sdo(data: bytes) -> bytes:
        (ack,) = node.handle(Frame(0x600 + NODE_ID, data), t0 & 0xFFFFFFFF)
        return ack.data

    assert sdo(bytes([0x2B, 0x17, 0x10, 0x00, 50, 0, 0, 0]))[0] == 0x60
    assert sdo(bytes([0x23, 0x10, 0x10, 0x01]) + od.SIGNATURE_SAVE.to_bytes(4, "little"))[0] == 0x60
    node.boot()  # the power cycle: the store opened again from the NVM, the node started again

    def heartbeats(start: int, stop: int) -> list[int]:
        return [t for t in range(start, stop) for f in node.tick(t & 0xFFFFFFFF) if f.can_id == 0x700 + NODE_ID]

    assert len(heartbeats(t0, t0 + 1)) == 1  # the first tick after boot is over any period
    beats = heartbeats(t0 + 1, t0 + 1001)
    assert len(beats) == 20 and set(b - a for a, b in zip(beats, beats[1:])) == {50}


@DIES
@pytest.mark.parametrize("mode", ["before", "torn", "after"])
@pytest.mark.parametrize("op", [1, 2])
def test_store_is_power_cut_safe(bdir, tmp_path, op, mode):
    """slipest_emu kills itself (SIGKILL) inside the K-th NVM write or erase of 0x1010's save (1: erasing the
    sector not holding the newest record, 2: programming the new record; before it, half of it, or right after
    it). The restarted node has the previous stored value or the new one, never the default or garbage: the new
    one only when the record was programmed completely."""
    nvm = tmp_path / "nvm.bin"
    with emulator_session(bdir, nvm) as s:
        for value in (60, 80):  # two records: 60 in the first parameter sector, 80 (the newest) in the second
            s.master.node.sdo[0x1017].raw = value
            s.master.store_parameters()
    with emulator_session(bdir, nvm, "--nvm-cut-after", str(op), "--nvm-cut-mode", mode) as s:
        s.master.node.sdo[0x1017].raw = 50  # to be saved over 60's record
        # the process dies before answering (python canopen's abort after its timeout then finds the pty gone)
        with pytest.raises((canopen.SdoCommunicationError, can.CanError)):
            s.master.store_parameters()
        assert s.proc.wait(timeout=10) == -9
    with emulator_session(bdir, nvm) as s:
        # the new record counts once it is programmed: completely (after), or its first half (torn), which holds
        # the whole 32-byte record in a 256-byte sector (a record torn inside itself fails its CRC: test_co.c)
        assert heartbeat_time(s) == (50 if op == 2 and mode != "before" else 80)


def test_store_and_restore_in_process_through_nmt_reset(bdir):
    """The same on the in-process node (RamNvm): saved, reset node keeps it, restore then reset gives the default;
    a power cycle reads the record back."""
    with CanopenSession("inproc", eds_for(bdir), NODE_ID, lib=find_artifact(bdir, "libslipest_host.so")) as s:
        s.master.node.sdo[0x1017].raw = 120
        s.master.store_parameters()
        s.master.node.sdo[0x1017].raw = 130
        s.reset_node()
        assert heartbeat_time(s) == 120
        s.power_cycle()
        assert heartbeat_time(s) == 120
        s.master.restore_defaults()
        s.power_cycle()
        assert heartbeat_time(s) == od.HEARTBEAT_MS


# --------------------------------------------------------------------------------------- refusals say why
def image_folder(root: Path, name: str, image: bytes) -> Path:
    d = root / name
    d.mkdir()
    (d / "model.img").write_bytes(image)
    return d


def error_line(err: str) -> str:
    """The one error line of a failed command (the progress bar shares stderr); no traceback."""
    lines = [line for line in err.splitlines() if line.startswith("fleetlab upload: error: ")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def upload_cli(capsys, *args: str) -> tuple[int, str, str]:
    rc = main(["upload", *args])
    out = capsys.readouterr()
    return rc, out.out, out.err


@pytest.mark.parametrize("kind, reason", [
    ("stale_version", "stale version: model version not newer than the active one"),
    ("wrong_arch", "architecture: model architecture or layer sizes differ"),
    ("corrupt_image", "corrupted image: CRC mismatch"),
    ("truncated", "size: DLC, packet or image length disagrees with its header"),
])
def test_upload_prints_the_nodes_reason(bdir, new_bundle, tmp_path, capsys, kind, reason):
    img = (new_bundle / "model.img").read_bytes()
    nvm = tmp_path / "nvm.bin"
    if kind == "stale_version":  # version 2 active: the same image again is not newer
        assert upload_cli(capsys, "--bundle", str(new_bundle), "--emulate", "--nvm", str(nvm), "--activate")[0] == 0
    bad = image_folder(tmp_path, "bad", faulty_image(kind, img))
    rc, _, err = upload_cli(capsys, "--bundle", str(bad), "--emulate", "--nvm", str(nvm), "--activate")
    line = error_line(err)
    assert rc == 1 and f"the node refused the image: {reason}" in line, line
    code = od.ABORT["LENGTH"] if kind == "truncated" else od.ABORT["STORE"]
    assert f"SDO abort 0x{code:08X}" in line


def test_upload_names_an_image_too_large_for_the_slots(bdir, new_bundle, tmp_path, capsys):
    img = (new_bundle / "model.img").read_bytes()
    big = image_folder(tmp_path, "big", img + bytes(100_000))
    rc, _, err = upload_cli(capsys, "--bundle", str(big), "--emulate")
    line = error_line(err)
    assert rc == 1 and "the node refused the image: size:" in line and f"SDO abort 0x{od.ABORT['TOO_HIGH']:08X}" in line


def test_rollback_after_a_refused_image_says_no_previous_model(bdir, new_bundle, tmp_path, capsys):
    """Two generations in the slots, `fleetlab upload --rollback` goes back and forth; then a refused image takes
    the rollback target's slot (an upload always goes into the slot that is not active) and a rollback, in a new
    process as after a reboot, answers "no previous model" in one line, not the refused image's CRC mismatch."""
    img = (new_bundle / "model.img").read_bytes()
    v3 = image_folder(tmp_path, "v3", image_layout.patch_header(img, model_version=3))
    nvm = tmp_path / "nvm.bin"
    emu = ("--emulate", "--nvm", str(nvm))
    rc, _, err = upload_cli(capsys, "--rollback", *emu)  # the built-in model: nothing to go back to
    assert rc == 1 and error_line(err) == (
        "fleetlab upload: error: no previous model to roll back to (none was active before this one, or an upload "
        "since has taken its slot, even one the node then refused)"), err
    assert upload_cli(capsys, "--bundle", str(new_bundle), "--activate", *emu)[0] == 0
    assert upload_cli(capsys, "--bundle", str(v3), "--activate", *emu)[0] == 0
    rc, out, _ = upload_cli(capsys, "--rollback", "--json", *emu)
    r = json.loads(out)
    assert rc == 0 and r["before"]["version"] == 3 and r["after"]["version"] == 2
    rc, out, _ = upload_cli(capsys, "--rollback", *emu)
    assert rc == 0 and out.startswith("rolled back  model version 2") and "-> version 3" in out
    # version 4, corrupted: refused; it was written into the slot of version 2, the rollback target
    v4 = image_folder(tmp_path, "v4", faulty_image("corrupt_image", image_layout.patch_header(img, model_version=4)))
    rc, _, err = upload_cli(capsys, "--bundle", str(v4), "--activate", *emu)
    assert rc == 1 and "corrupted image: CRC mismatch" in error_line(err)
    rc, _, err = upload_cli(capsys, "--rollback", *emu)
    assert rc == 1 and "no previous model to roll back to" in error_line(err) and err.count("\n") == 1, err
    assert "CRC" not in err and "-7" not in err
    assert upload_cli(capsys, "--rollback", "--json", *emu)[0] == 1  # nothing changed: still version 3
    with emulator_session(bdir, nvm) as s:
        assert s.master.active_model()["version"] == 3


def test_emulator_rollback_after_a_refused_image_says_no_previous_model(bdir, new_bundle, tmp_path):
    """The same through slipest_emu's own store commands (--upload / --rollback, one process each)."""
    emu = find_artifact(bdir, EMULATOR_TARGET)
    img = (new_bundle / "model.img").read_bytes()
    nvm = tmp_path / "nvm.bin"

    def run(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([str(emu), "--nvm", str(nvm), *args], capture_output=True, text=True, timeout=60)

    for version in (2, 3):
        f = tmp_path / f"v{version}.img"
        f.write_bytes(image_layout.patch_header(img, model_version=version))
        assert run("--upload", str(f), "--activate").returncode == 0
    bad = tmp_path / "bad.img"
    bad.write_bytes(faulty_image("corrupt_image", image_layout.patch_header(img, model_version=4)))
    assert run("--upload", str(bad)).returncode != 0
    res = run("--rollback")
    assert res.returncode == 3 and "rollback refused: no previous model" in res.stderr, res.stderr
    assert "CRC mismatch" not in res.stderr


def test_uploaded_refused_image_keeps_its_status_in_the_status_object(bdir, new_bundle, tmp_path):
    """0x2006 sub 2 (last store status) holds the refusal's reason after the transfer ended, as the EMCY's byte 3
    does: the end of the aborted transfer does not overwrite it."""
    from fleetlab.host_tools.status_codes import status

    img = (new_bundle / "model.img").read_bytes()
    with CanopenSession("inproc", eds_for(bdir), NODE_ID, lib=find_artifact(bdir, "libslipest_host.so")) as s:
        with pytest.raises(canopen.SdoAbortedError):
            s.master.upload(faulty_image("wrong_arch", img))
        assert s.master.upload_status()["last_store_status"] == status()["SLIPEST_E_ARCH"]

