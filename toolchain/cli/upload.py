"""`fleetlab upload`: send a bundle's model image to a running slipest CANopen node by CiA 302-3 program
download (clear, SDO block download of 0x1F50 into its inactive slot), start it when asked (on trial) and
confirm it (0x1F51 = 0x80; after --rehearse only when the rehearsal passed; never with --no-confirm), read back
the active version and hash.
The library part is `fleetlab.host_tools.upload`."""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

from fleetlab.canopen_od import eds_text
from fleetlab.host_tools.canopen_session import CobsCanBus, eds_for
from fleetlab.host_tools.links import open_can_bus
from fleetlab.export.image_layout import V2, layout_of
from fleetlab.host_tools.upload import open_tapped, read_image, rehearse, rollback_model, upload_image
from ..errors import InputError

from . import options


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--bundle", type=Path, default=None, help="export bundle whose model.img is sent (required unless "
                                                             "--rollback)")
    p.add_argument("--rollback", action="store_true",
                   help="send no image: the node re-activates its previous model (0x2002 = 1); says so in one line "
                        "when it has none")
    p.add_argument("--link", choices=("canopen", "serial"), default="canopen",
                   help="canopen: a CAN bus (python-can --interface/--channel); serial: the same CAN frames in "
                        "COBS packets on --port")
    p.add_argument("--interface", default="slcan", help="python-can interface for --link canopen (default slcan)")
    p.add_argument("--channel", default=None, help="CAN channel for --link canopen (/dev/ttyACM0, can0, ...)")
    p.add_argument("--bitrate", type=int, default=500000, help="CAN bit rate for slcan/socketcan (default 500000)")
    p.add_argument("--port", default=None, help="serial device for --link serial")
    p.add_argument("--node-id", type=int, default=5, help="CANopen node id of the estimator (default 5)")
    p.add_argument("--activate", action="store_true",
                   help="start the image after it passed validation (CiA 302-3 start: on trial, the node boots up) "
                        "and confirm it (0x1F51 = 0x80)")
    p.add_argument("--no-confirm", action="store_true",
                   help="with --activate or --rehearse: leave the new model on trial; the next reset or power cut "
                        "brings the previous one back (confirm later by writing 0x80 to 0x1F51)")
    p.add_argument("--segmented", action="store_true", help="SDO segmented download instead of block download")
    p.add_argument("--emulate", action="store_true",
                   help="no hardware: start the emulator (slipest_emu --profile canopen) on a pty and upload to it")
    p.add_argument("--nvm", type=Path, default=None, metavar="FILE",
                   help="with --emulate: the emulator's NVM file (kept between runs; default: a fresh one)")
    p.add_argument("--boot-bundle", type=Path, default=None, metavar="DIR",
                   help="with --emulate: the node boots on this bundle's model.img (e.g. the Earth-analog model)")
    p.add_argument("--rehearse", type=int, default=0, metavar="N",
                   help="check the update on the running node: stream N windows of simulated telemetry during the "
                        "upload (every one answered by the old model, bit-exact), activate, stream N more (the new "
                        "model's torch integer reference, bit-exact)")
    p.add_argument("--seed", type=int, default=1, help="simulator seed of --rehearse (default 1)")
    p.add_argument("--scale", type=float, default=0.3, help="simulator scale of --rehearse (default 0.3)")
    p.add_argument("--report", type=Path, default=None, metavar="FILE", help="also write the report as JSON to FILE")
    p.add_argument("--json", action="store_true", help="print the report as one JSON object")
    options.no_progress(p)


def _is_table_image(image: bytes) -> bool:
    """A format-2 (layer-table) image; an unreadable format is left for the node to refuse."""
    try:
        return layout_of(image) is V2
    except ValueError:
        return False


def _rollback(session, before: dict, args: argparse.Namespace) -> int:
    after = rollback_model(session)  # OSError (one line) when the node has no previous model
    result = {"before": {"version": before["version"], "hash32": f"{before['hash32']:08x}"},
              "after": {"version": after["version"], "hash32": f"{after['hash32']:08x}", "sha256": after["sha256"],
                        "slot": after["slot"]}}
    if args.report:
        args.report.write_text(json.dumps(result, indent=1))
    if args.json:
        print(json.dumps(result))
    else:
        print(f"rolled back  model version {before['version']} hash {before['hash32']:08x} -> version "
              f"{after['version']} hash {after['hash32']:08x} (slot {after['slot']})")
    return 0


def run(args: argparse.Namespace) -> int:
    from tqdm.auto import tqdm

    if not 1 <= args.node_id <= 127:
        raise InputError("--node-id must be 1..127")
    if args.rollback and (args.bundle is not None or args.activate or args.rehearse):
        raise InputError("--rollback sends no image: it takes no --bundle, --activate or --rehearse")
    if not args.rollback and args.bundle is None:
        raise InputError("--bundle is required (or --rollback)")
    if args.no_confirm and not (args.activate or args.rehearse):
        raise InputError("--no-confirm needs --activate or --rehearse (nothing is started otherwise)")
    image = b"" if args.rollback else read_image(args.bundle)
    with tempfile.TemporaryDirectory() as tmp:
        if args.emulate:
            from fleetlab.host_tools.emulator import EMULATOR_TARGET, build, find_artifact

            # a layer-table (format-2) image needs a node built with the layer-table kernels and reader; the
            # emulated node still boots on the example SN-S model
            table = _is_table_image(image)
            bdir = build(None, targets=(EMULATOR_TARGET,), options={"SLIPEST_LAYER_TABLE": "ON"} if table else None)
            nvm = args.nvm or Path(tmp) / "nvm.bin"
            boot = None
            if args.boot_bundle is not None:
                read_image(args.boot_bundle)  # a clear error when it has no model.img
                boot = args.boot_bundle / "model.img"
            session, tap = open_tapped("slcan" if args.link == "canopen" else "cobs", eds_for(bdir), args.node_id,
                                       emulator=find_artifact(bdir, EMULATOR_TARGET), nvm_file=nvm,
                                       builtin_image=boot)
        else:
            eds = Path(tmp) / "slipest.eds"
            eds.write_text(eds_text())  # the node's EDS, from the same source as its C tables
            if args.link == "canopen":
                if args.channel is None and args.interface != "virtual":
                    raise InputError("--link canopen needs --channel (or --emulate)")
                kw = {"bitrate": args.bitrate} if args.interface in ("slcan", "socketcan") else {}
                bus = open_can_bus(args.interface, args.channel, **kw)
            else:
                if args.port is None:
                    raise InputError("--link serial needs --port (or --emulate)")
                bus = CobsCanBus(args.port)
            session, tap = open_tapped("bus", eds, args.node_id, bus=bus)
        with session:
            before = session.master.active_model()
            if args.rollback:
                return _rollback(session, before, args)
            bar = tqdm(total=len(image), unit="B", unit_scale=True, desc="upload", disable=args.json or args.no_progress,
                       file=sys.stderr)
            try:
                if args.rehearse > 0:
                    if args.boot_bundle is None:
                        raise InputError("--rehearse needs --boot-bundle (the model the node runs before the update)")
                    result = rehearse(session, tap, image, args.bundle, args.boot_bundle, args.rehearse,
                                      seed=args.seed, scale=args.scale, block=not args.segmented,
                                      progress=bar.update, confirm=not args.no_confirm)
                else:
                    result = None
                    report = upload_image(session, tap, image, args.activate, block=not args.segmented,
                                          progress=bar.update, confirm=not args.no_confirm)
            finally:
                bar.close()
    if result is not None:
        if args.report:
            args.report.write_text(json.dumps(result, indent=1))
        up = result["upload"]
        if args.json:
            print(json.dumps(result))
        else:
            print(f"image        {up['image_bytes']} bytes, {up['sdo_frames']} SDO frames, "
                  f"{up['bus_time_s_at_500k'] * 1000:.1f} ms at 500 kbit/s")
            print(f"windows      {result['windows_answered_during_upload_phase']} of "
                  f"{result['windows_streamed_during_upload_phase']} answered around the upload "
                  f"({up['windows_during_upload']} while it ran), old model bit-exact: {result['boot_model_bit_exact']}")
            print(f"activated    version {result['before']['version']} -> {result['after']['version']} "
                  f"(hash {result['after']['hash32']}); next {result['windows_after_activation']} windows bit-exact "
                  f"with the new model: {result['new_model_bit_exact']}")
            print("confirmed    yes" if result["confirmed"] else
                  "confirmed    no: on trial, the next reset brings the previous model back")
        ok = result["boot_model_bit_exact"] and result["new_model_bit_exact"] and \
            result["windows_answered_during_upload_phase"] == result["windows_streamed_during_upload_phase"]
        return 0 if ok else 1
    if args.report:
        args.report.write_text(json.dumps(report.as_dict(), indent=1))
    if args.json:
        print(json.dumps({"before": {"version": before["version"], "hash32": f"{before['hash32']:08x}"},
                          **report.as_dict()}))
        return 0
    print(f"image        {report.image_bytes} bytes ({args.bundle / 'model.img'})")
    print(f"transfer     {report.sdo_frames} SDO frames, {report.bus_bits} bits on the bus: "
          f"{report.bus_time_s_at_500k * 1000:.1f} ms at 500 kbit/s ({report.wall_time_s * 1000:.0f} ms here)")
    print(f"before       model version {before['version']} hash {before['hash32']:08x}")
    state = ("active, confirmed" if report.confirmed else "active on trial (not confirmed: a reset reverts it)") \
        if report.activated else "uploaded, not activated (run again with --activate)"
    print(f"now          model version {report.active_version} hash {report.active_hash32} ({state})")
    return 0
