"""The slipest CANopen node's object dictionary: the ONE source of both the C tables
(generated at build time into slipest_co_od.c/.h) and the EDS (CiA 306) file.

Pure data and stdlib only: CMake runs `generate.py` with whatever Python it finds.

Each entry: (index, sub, name, data type, access, default, kind, arg, pdo_mappable).
`kind` names where the C node keeps the value (a handler in slipest_co_od_access.c):
  const      the default itself (plus the node id when `default` is a "$NODEID+..." string)
  hb_time    producer heartbeat time 0x1017 (read/write)
  err_reg    error register 0x1001
  serial     identity serial number (given to slipest_co_init)
  pdo        bytes of the last payload of a PDO: arg = payload buffer << PDO_SHIFT | byte offset
  model      the active model: arg = position in MODEL_ARGS
  counter    node counter number arg (slipest_co_counter())
  slot       slot arg >> SLOT_SHIFT, field (low bits) = position in SLOT_FIELDS
  store_cnt  store counter number arg (slipest_store_counters_t field order)
  upload     arg = position in UPLOAD_ARGS (upload state, last store status, bytes received)
  command    write-only command arg = command_arg(name) for COMMAND_ARGS (rollback: CiA 302-3 has none)
  domain     the model image, CiA 302-3 program data 0x1F50 sub 1 (DOMAIN): written into the inactive slot, only
             after a clear; a read is the active image
  prog_ctrl  CiA 302-3 program control 0x1F51 sub 1: a write is a PROGRAM_CONTROL command, a read PROGRAM_STATES
  flash      CiA 302-3 flash status identification 0x1F57 sub 1 (see FLASH_STATUS_* below)
  params     CiA 301 store (0x1010) / restore (0x1011) parameters: arg = position in PARAM_ARGS; reads 1 (the
             node saves / restores on command; 0 without a store), a write needs the signature
PDO communication and mapping objects (0x1400/0x1600/0x1800/0x1A00) are derived from PDOS.
"""

from __future__ import annotations

# CiA 301 data type codes
BOOLEAN, INTEGER8, INTEGER16, INTEGER32 = 0x01, 0x02, 0x03, 0x04
UNSIGNED8, UNSIGNED16, UNSIGNED32 = 0x05, 0x06, 0x07
VISIBLE_STRING, OCTET_STRING, DOMAIN = 0x09, 0x0A, 0x0F
TYPE_BYTES = {BOOLEAN: 1, INTEGER8: 1, INTEGER16: 2, INTEGER32: 4, UNSIGNED8: 1, UNSIGNED16: 2, UNSIGNED32: 4,
              OCTET_STRING: 32, DOMAIN: 0}
SIGNED = {INTEGER8, INTEGER16, INTEGER32}

# Identity (0x1018). Not a CiA-assigned vendor ID: an integrator puts their own here.
VENDOR_ID = 0x00000000
PRODUCT_CODE = 0x534C5031  # "SLP1"
REVISION = 0x00010000  # major 1, minor 0 (slipest library 1.0)
DEVICE_TYPE = 0x00000000  # no CiA device profile
HEARTBEAT_MS = 1000
DEVICE_NAME = "slipest"

# The object dictionary's own version: the EDS's FileVersion / FileRevision, and the date of that version as its
# ModificationDate (CiA 306 [FileInfo]). Written here, never taken from the clock, so the generated EDS is the same
# bytes on every machine and every day (tests/test_determinism.py). Raise OD_VERSION and set OD_VERSION_DATE
# whenever an object changes. CiA 306 dates are mm-dd-yyyy, times hh:mm(AM|PM).
# 2.0: 0x1010 / 0x1011 (store and restore parameters); 0x2001 sub 3 readable in every state
# 3.0: CiA 302-3 program download 0x1F50 / 0x1F51 / 0x1F56 / 0x1F57, trial activation (0x1F51 = 0x80 confirms),
#      0x2005 sub 16 trial reverts
# 4.0: the manufacturer duplicates of 0x1F50 / 0x1F51 gone: 0x2000 (model image; 0x1F50 sub 1 after a clear),
#      0x2002 sub 1 activate (0x1F51 = 1, then 0x80) and sub 3 abort (0x1F51 = 3); 0x2002 is the rollback command
#      alone, a VAR (sub 0), so that a master written for 3.0 that writes 0x2002 sub 1 or 3 gets "sub-index does
#      not exist" instead of another command (issue 45: the manufacturer objects stay for what 302-3 lacks)
OD_VERSION = (4, 0)
OD_CREATED = ("11-24-2026", "12:00PM")  # the first version of this dictionary
OD_VERSION_DATE = ("12-03-2026", "12:00PM")

# CiA 301 store / restore parameters (0x1010 / 0x1011 sub 1): the signatures a master writes, "save" and "load" as
# four ASCII bytes in SDO (little-endian) order
SIGNATURE_SAVE = int.from_bytes(b"save", "little")  # 0x65766173
SIGNATURE_LOAD = int.from_bytes(b"load", "little")  # 0x64616F6C
IDX_STORE_PARAMS = 0x1010
IDX_RESTORE_PARAMS = 0x1011
# The writable communication parameters 0x1010 stores (in the parameter record's order, each little-endian in its
# type's size) and 0x1011 restores to their defaults, after a reset. generate.py refuses a writable communication
# object that is not here: the C node packs exactly these (slipest_co_od_access.c).
STORED_PARAMS = (0x1017,)

# CiA 302-3 program download: the model is the node's "program". A generic master needs these four and nothing of
# fleetlab's (docs/model_update.md); sub 1 of each is program number 1, the one model the node runs.
IDX_PROGRAM_DATA = 0x1F50  # DOMAIN: write = an image into the inactive slot (after a clear), read = the active image
IDX_PROGRAM_CONTROL = 0x1F51  # UNSIGNED8: PROGRAM_CONTROL commands, read PROGRAM_STATES
IDX_PROGRAM_SWID = 0x1F56  # UNSIGNED32: the running model's hash32 (first 4 bytes of its sha256, big-endian)
IDX_FLASH_STATUS = 0x1F57  # UNSIGNED32: bit 0 busy, bits 1-7 FLASH_STATUS code, bits 16-23 the slipest status
# 0x1F51 writes (CiA 302-3; 0x80 "confirm" is the code Zephyr's program download and MCUboot-style masters send)
PROGRAM_CONTROL = (("stop", 0), ("start", 1), ("reset", 2), ("clear", 3), ("confirm", 0x80))
# 0x1F51 reads
PROGRAM_STATES = (("stopped", 0), ("started", 1), ("no_program", 3))
# 0x1F57 bits 1-7 (CiA 302-3 flash status error codes): (C name, code, meaning)
FLASH_STATUS = (
    ("OK", 0, "no error"),
    ("NO_VALID_PROGRAM", 1, "no valid program (start with nothing downloaded that could run)"),
    ("UNKNOWN_FORMAT", 2, "unknown format (not a model image: magic, image format version)"),
    ("FORMAT_ERROR", 3, "format error (length, architecture, CRC, hash or a model check)"),
    ("NOT_CLEARED", 4, "flash not cleared before write (0x1F50 written without 0x1F51 = 3)"),
    ("WRITE_ERROR", 5, "flash write error (the NVM failed)"),
    ("ADDRESS_ERROR", 6, "general address error (the image is larger than a slot)"),
    ("SECURED", 7, "flash secured (authentication failed, or a model version not newer than the running one)"),
    ("UNSPECIFIED", 63, "unspecified error"),
)
FLASH_BUSY = 0x1  # bit 0: a download is open
FLASH_CODE_SHIFT = 1
FLASH_SLIPEST_SHIFT = 16  # bits 16-23 (manufacturer-specific): the slipest status of the last store call
# the 302-3 code of each slipest status a store call refuses with (slipest_status.h names); any other: UNSPECIFIED
FLASH_BY_STATUS = {"SLIPEST_E_LENGTH": "FORMAT_ERROR", "SLIPEST_E_FORMAT": "UNKNOWN_FORMAT",
                   "SLIPEST_E_VERSION": "UNKNOWN_FORMAT", "SLIPEST_E_ARCH": "FORMAT_ERROR", "SLIPEST_E_CRC": "FORMAT_ERROR",
                   "SLIPEST_E_HASH": "FORMAT_ERROR", "SLIPEST_E_RANGE": "FORMAT_ERROR",
                   "SLIPEST_E_NONFINITE": "FORMAT_ERROR", "SLIPEST_E_NVM": "WRITE_ERROR", "SLIPEST_E_AUTH": "SECURED",
                   "SLIPEST_E_STALE": "SECURED"}
FLASH = {name: code for name, code, _ in FLASH_STATUS}

# Manufacturer objects: only what CiA 302-3 has no object for (model details, rollback, counters, slot table, upload
# progress; docs/model_update.md lists each with its 302-3 counterpart). 0x2000 is no longer used (OD 4.0).
IDX_ACTIVE_MODEL = 0x2001
IDX_ROLLBACK = 0x2002
IDX_COUNTERS = 0x2003
IDX_SLOTS = 0x2004
IDX_STORE_COUNTERS = 0x2005
IDX_UPLOAD = 0x2006

# SDO abort codes (CiA 301) the node's server sends or its master side names: (C name, code, meaning).
# The one source of slipest_co_od.h's SLIPEST_CO_ABORT_* and of the host's names for them.
ABORT_CODES = (
    ("TOGGLE", 0x05030000, "toggle bit not alternated"),
    ("TIMEOUT", 0x05040000, "SDO protocol timed out"),
    ("COMMAND", 0x05040001, "command specifier not valid or unknown"),
    ("SEQUENCE", 0x05040003, "invalid sequence number (block mode)"),
    ("CRC", 0x05040004, "CRC error (block mode)"),
    ("UNSUPPORTED", 0x06010000, "unsupported access to an object"),
    ("WRITE_ONLY", 0x06010001, "attempt to read a write-only object"),
    ("READ_ONLY", 0x06010002, "attempt to write a read-only object"),
    ("NO_OBJECT", 0x06020000, "object does not exist"),
    ("HARDWARE", 0x06060000, "access failed: hardware (NVM) error"),
    ("LENGTH", 0x06070010, "length of the service parameter does not match"),
    ("TOO_HIGH", 0x06070012, "length too high"),
    ("TOO_LOW", 0x06070013, "length too low"),
    ("NO_SUB", 0x06090011, "sub-index does not exist"),
    ("VALUE", 0x06090030, "invalid value (a command other than 1)"),
    ("GENERAL", 0x08000000, "general error"),
    ("STORE", 0x08000020, "data cannot be stored (image refused)"),
    ("STATE", 0x08000022, "not in the present device state (no store, nothing to activate)"),
    ("NO_DATA", 0x08000024, "no data available (not sent since OD 2.0: every readable object answers)"),
)
# EMCY error codes (CiA 301) the node sends: (C name, code, meaning), the source of SLIPEST_CO_EMCY_*.
EMCY_CODES = (
    ("RESET", 0x0000, "error reset: the error register is clear again"),
    ("HARDWARE", 0x5000, "an NVM callback failed"),
    ("DATA_SET", 0x6300, "a model image was refused (byte 3: slipest status)"),
    ("TRIAL_REVERTED", 0xFF01, "device specific: a model on trial met a reset before its confirm; the previous runs"),
    ("PDO_LENGTH", 0x8210, "an RPDO had the wrong length"),
    ("NO_MODEL", 0xFF00, "device specific: no model to run (none built in, no valid slot)"),
)
ABORT = {name: code for name, code, _ in ABORT_CODES}
EMCY = {name: code for name, code, _ in EMCY_CODES}

# The arguments of the kinds (what the C node's handler switches on), by name: generate.py writes
# them into slipest_co_od.h as SLIPEST_CO_<KIND>_<NAME>, so neither side spells a bare number.
MODEL_ARGS = ("version", "hash32", "sha256", "slot", "library_version")
COMMAND_ARGS = ("rollback",)  # arg = 1 + position (the value written must be 1)
UPLOAD_ARGS = ("state", "last_status", "received")
PARAM_ARGS = ("save", "restore")  # 0x1010 sub 1, 0x1011 sub 1
SLOT_SHIFT = 4  # slot arg: slot << SLOT_SHIFT | position of the field in SLOT_FIELDS
PDO_SHIFT = 3  # pdo arg: payload buffer << PDO_SHIFT | byte offset


def command_arg(name: str) -> int:
    return 1 + COMMAND_ARGS.index(name)


# the estimator's own counters (slipest_counters_t, in its field order: the C build checks the names
# through offsetof, tests/test_canopen_od.py the order), then the CANopen node's
ESTIMATOR_COUNTERS = ("frames_received", "frames_rejected", "samples_dropped", "windows_flagged", "windows_done",
                      "saturations")
COUNTERS = ESTIMATOR_COUNTERS + ("rpdo_received", "sdo_aborts_sent", "sdo_aborts_received", "emcy_sent",
            "block_sequence_errors", "nmt_commands", "frames_ignored", "rpdo_no_model")
# slipest_store_counters_t's fields in the order 0x2005 lists them (any order: read through offsetof)
STORE_COUNTERS = ("uploads_started", "uploads_aborted", "images_accepted", "refused_length", "refused_format",
                  "refused_arch", "refused_crc", "refused_hash", "refused_range", "refused_hmac", "refused_version",
                  "activations", "rollbacks", "nvm_errors", "boot_fallbacks", "trial_reverts")
SLOT_FIELDS = (("state", UNSIGNED8), ("length", UNSIGNED32), ("version", UNSIGNED32), ("hash32", UNSIGNED32))

# PDO-mapped records. Payload layouts equal the DBC frames (dbc/slipest.dbc, little-endian),
# so the CANopen profile carries the plain profile's bytes: tests/test_canopen_od.py checks it.
PDO_RECORDS = {
    0x2100: ("Telemetry wheel", "TELEM_WHEEL",
             (("sample_counter", UNSIGNED16), ("wheel_speed", INTEGER16), ("motor_current", INTEGER16))),
    0x2101: ("Telemetry IMU", "TELEM_IMU",
             (("sample_counter", UNSIGNED16), ("acc_x", INTEGER16), ("acc_y", INTEGER16), ("acc_z", INTEGER16))),
    0x2102: ("Telemetry attitude", "TELEM_ATTITUDE",
             (("sample_counter", UNSIGNED16), ("roll", INTEGER16), ("pitch", INTEGER16))),
    0x2110: ("Slip estimate", "SLIP_ESTIMATE",
             (("window_counter", UNSIGNED16), ("slip_class", UNSIGNED8), ("slip_class_f32", UNSIGNED8),
              ("flags", UNSIGNED8), ("n_samples", UNSIGNED8), ("saturations", UNSIGNED16))),
    0x2111: ("Slip logits 01", "SLIP_LOGITS_01", (("logit_0", INTEGER32), ("logit_1", INTEGER32))),
    0x2112: ("Slip logit 2", "SLIP_LOGITS_2", (("logit_2", INTEGER32), ("window_counter", UNSIGNED16))),
    # not a DBC frame: the CANopen status carries the active model's hash32 and version
    0x2113: ("Model status", None, (("model_hash32", UNSIGNED32), ("model_version", UNSIGNED32))),
}

# (direction, number 1..4, mapped record). COB-IDs are the predefined connection set of the
# node id: RPDOn = 0x100 + 0x100 n + id, TPDOn = 0x080 + 0x100 n + id.
PDOS = (
    ("rx", 1, 0x2100),
    ("rx", 2, 0x2101),
    ("rx", 3, 0x2102),
    ("tx", 1, 0x2110),
    ("tx", 2, 0x2111),
    ("tx", 3, 0x2112),
    ("tx", 4, 0x2113),
)


def pdo_cob_base(direction: str, number: int) -> int:
    return (0x100 + 0x100 * number) if direction == "rx" else (0x080 + 0x100 * number)


def pdo_slot(direction: str, number: int) -> int:
    """Index of a PDO's payload buffer in the C node: RPDOs first, then TPDOs."""
    n_rx = sum(1 for d, _, _ in PDOS if d == "rx")
    return number - 1 if direction == "rx" else n_rx + number - 1


class Entry:
    __slots__ = ("index", "sub", "name", "dtype", "access", "default", "kind", "arg", "mappable", "parent")

    def __init__(self, index, sub, name, dtype, access, default=0, kind="const", arg=0, mappable=False, parent=None):
        self.index, self.sub, self.name, self.dtype, self.access = index, sub, name, dtype, access
        self.default, self.kind, self.arg, self.mappable, self.parent = default, kind, arg, mappable, parent


def _record(index, name, subs):
    """A RECORD: sub 0 (highest sub-index) then the given (name, type, access, default, kind, arg[, mappable])."""
    out = [Entry(index, 0, "Highest sub-index supported", UNSIGNED8, "const", len(subs), parent=name)]
    for k, s in enumerate(subs, start=1):
        out.append(Entry(index, k, *s, parent=name))
    return out


def objects() -> list[Entry]:
    """Every object of the node, sorted by (index, sub)."""
    e: list[Entry] = [
        Entry(0x1000, 0, "Device type", UNSIGNED32, "const", DEVICE_TYPE),
        Entry(0x1001, 0, "Error register", UNSIGNED8, "ro", 0, "err_reg"),
        Entry(0x1017, 0, "Producer heartbeat time", UNSIGNED16, "rw", HEARTBEAT_MS, "hb_time"),
    ]
    # default 1: what a read answers (saves / restores on command); a write takes the signature only
    e += _record(IDX_STORE_PARAMS, "Store parameters", [
        ("Save all parameters", UNSIGNED32, "rw", 1, "params", PARAM_ARGS.index("save")),
    ])
    e += _record(IDX_RESTORE_PARAMS, "Restore default parameters", [
        ("Restore all default parameters", UNSIGNED32, "rw", 1, "params", PARAM_ARGS.index("restore")),
    ])
    e += _record(0x1018, "Identity object", [
        ("Vendor-ID", UNSIGNED32, "ro", VENDOR_ID),
        ("Product code", UNSIGNED32, "ro", PRODUCT_CODE),
        ("Revision number", UNSIGNED32, "ro", REVISION),
        ("Serial number", UNSIGNED32, "ro", 0, "serial"),
    ])
    e += _record(0x1200, "SDO server parameter", [
        ("COB-ID client to server", UNSIGNED32, "ro", "$NODEID+0x600"),
        ("COB-ID server to client", UNSIGNED32, "ro", "$NODEID+0x580"),
    ])
    for direction, number, rec in PDOS:
        base = pdo_cob_base(direction, number)
        comm = (0x1400 if direction == "rx" else 0x1800) + number - 1
        mapping = (0x1600 if direction == "rx" else 0x1A00) + number - 1
        kind = "RPDO" if direction == "rx" else "TPDO"
        e += _record(comm, f"{kind}{number} communication parameter", [
            ("COB-ID used by PDO", UNSIGNED32, "ro", f"$NODEID+0x{base:X}"),
            ("Transmission type", UNSIGNED8, "ro", 0xFF),  # event-driven (manufacturer-specific)
        ])
        _, _, fields = PDO_RECORDS[rec]
        # "map" (argument: the mapped record): the node computes each value from the mapped sub-index
        # (slipest_co_od_access.c), so its tables keep no copy of it; the value here is what the EDS and the docs
        # show, and generate.py checks that the two agree
        e += _record(mapping, f"{kind}{number} mapping parameter", [
            (f"Mapped object {k}", UNSIGNED32, "ro", (rec << 16) | (k << 8) | (8 * TYPE_BYTES[t]), "map", rec)
            for k, (_, t) in enumerate(fields, start=1)
        ])
    e += _record(IDX_PROGRAM_DATA, "Program data", [("Program number 1", DOMAIN, "rw", 0, "domain")])
    e += _record(IDX_PROGRAM_CONTROL, "Program control", [("Program number 1", UNSIGNED8, "rw", 0, "prog_ctrl")])
    e += _record(IDX_PROGRAM_SWID, "Program software identification",
                 [("Program number 1", UNSIGNED32, "ro", 0, "model", MODEL_ARGS.index("hash32"))])
    e += _record(IDX_FLASH_STATUS, "Flash status identification", [("Program number 1", UNSIGNED32, "ro", 0, "flash")])
    e += _record(IDX_ACTIVE_MODEL, "Active model", [
        ("version", UNSIGNED32, "ro", 0, "model", MODEL_ARGS.index("version")),
        ("hash32", UNSIGNED32, "ro", 0, "model", MODEL_ARGS.index("hash32")),
        ("sha256", OCTET_STRING, "ro", 0, "model", MODEL_ARGS.index("sha256")),
        ("slot", UNSIGNED8, "ro", 0, "model", MODEL_ARGS.index("slot")),  # 0xFF: the built-in model, 0xFE: none
        ("library version", UNSIGNED16, "ro", 0, "model", MODEL_ARGS.index("library_version")),
    ])
    # write 1: back to the previous slot's model (302-3 has no rollback)
    e.append(Entry(IDX_ROLLBACK, 0, "Model rollback", UNSIGNED8, "wo", 0, "command", command_arg("rollback")))
    e += _record(IDX_COUNTERS, "Node counters",
                 [(n, UNSIGNED32, "ro", 0, "counter", k) for k, n in enumerate(COUNTERS)])
    e += _record(IDX_SLOTS, "Model slots",
                 [(f"slot {s} {f}", t, "ro", 0, "slot", (s << SLOT_SHIFT) | k) for s in (0, 1)
                  for k, (f, t) in enumerate(SLOT_FIELDS)])
    e += _record(IDX_STORE_COUNTERS, "Store counters",
                 [(n, UNSIGNED32, "ro", 0, "store_cnt", k) for k, n in enumerate(STORE_COUNTERS)])
    e += _record(IDX_UPLOAD, "Upload status", [
        ("state", UNSIGNED8, "ro", 0, "upload", UPLOAD_ARGS.index("state")),
        ("last store status", INTEGER8, "ro", 0, "upload", UPLOAD_ARGS.index("last_status")),
        ("bytes received", UNSIGNED32, "ro", 0, "upload", UPLOAD_ARGS.index("received")),
    ])
    for rec, (name, _, fields) in PDO_RECORDS.items():
        direction, number = next((d, n) for d, n, r in PDOS if r == rec)
        slot = pdo_slot(direction, number)
        access = "rww" if direction == "rx" else "ro"
        subs, off = [], 0
        for fname, t in fields:
            subs.append((fname, t, access, 0, "pdo", (slot << PDO_SHIFT) + off, True))
            off += TYPE_BYTES[t]
        e += _record(rec, name, subs)
    e.sort(key=lambda x: (x.index, x.sub))
    return e
