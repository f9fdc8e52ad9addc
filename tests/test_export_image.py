"""model.img written by `fleetlab export`: the Python writer and reader round-trip, and the reader
refuses what the C reader refuses (the C reader itself: tests/test_firmware.py)."""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fleetlab.export import image_layout, model_image, sns_profile
from fleetlab.export.bundle import load_bundle

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "firmware_c" / "bundles" / "example"


def test_writer_reader_roundtrip() -> None:
    b = load_bundle(EXAMPLE)
    data = model_image.image_bytes(b.qparams, b.fparams, b.content_hash, model_version=5)
    assert len(data) == 3842 and data[:4] == b"SLPM"
    img = model_image.read_image(data)
    assert img.model_version == 5 and img.content_hash == b.content_hash
    for name, arr in sns_profile.q_arrays(img.qnet).items():
        assert np.array_equal(arr, np.asarray(sns_profile.q_arrays(b.qparams)[name])), name
    for name, arr in sns_profile.f32_arrays(img.fnet).items():
        assert np.array_equal(arr, sns_profile.f32_arrays(b.fparams)[name]), name
    blk = b.qparams.blocks[0]
    assert img.header["fy"] == blk.fy and img.header["eps_m"] == blk.eps_m
    # explicit little-endian: w1[0][0] sits right after the header, low byte first, whatever the host's order
    assert struct.unpack_from("<h", data, image_layout.CURRENT.header_size)[0] == int(blk.w[0, 0])


def test_bundle_image_is_the_bundles_model() -> None:
    b = load_bundle(EXAMPLE)
    data = (EXAMPLE / "model.img").read_bytes()
    assert data == model_image.image_bytes(b.qparams, b.fparams, b.content_hash, b.manifest["model_version"])


def test_committed_format1_image_still_loads() -> None:
    """The committed example's model.img is a format-1 image, the format of the images already on rovers: the
    one reader reads it as the one-block network of width 30, holding exactly its headers' parameters. (The C
    reader loads the same file: tests/test_firmware.py::test_emulator_runs_the_model_image_bit_exact.)"""
    data = (EXAMPLE / "model.img").read_bytes()
    b = load_bundle(EXAMPLE)
    assert image_layout.layout_of(data) is image_layout.V1 and image_layout.header_fields(data)["arch"] == 1
    img = model_image.read_image(data)
    assert img.format_version == 1 and img.qnet.hidden == img.fnet.hidden == (30,)
    assert model_image.same_model(img, b.qparams) and img.content_hash == b.content_hash
    got, want = img.fnet.blocks[0], b.fparams.blocks[0]
    assert all(np.array_equal(getattr(got, k), getattr(want, k)) for k in ("w", "b", "gamma", "beta"))
    assert np.array_equal(img.fnet.w_out, b.fparams.w_out) and np.array_equal(img.fnet.b_out, b.fparams.b_out)
    assert img.fnet.eps == b.fparams.eps


@pytest.mark.parametrize("fields, match", [
    ({"n_hidden": 29}, "not format 1's"), ({"arch": 2}, "architecture 2"), ({"fy": 40}, "fy=40"),
    ({"fz": 11}, "not the scheme's"), ({"gelu_n": 128}, "table sizes"),
])
def test_format1_reader_refuses_what_the_c_reader_refuses(fields, match) -> None:
    """The header edits tests/test_firmware.py sends to the C reader (resealed, so the CRC passes) are refused by
    the Python reader too: a width that is not SN-S's, another architecture, a shift out of range or not the
    scheme's for the width."""
    data = (EXAMPLE / "model.img").read_bytes()
    with pytest.raises(ValueError, match=match):
        model_image.read_image(image_layout.patch_header(data, **fields))


def test_format1_is_the_table_layouts_sn_s_profile() -> None:
    """Format 1 is the layer-table description with its widths fixed to (30,) and its one record in the header:
    the same arrays as format 2 (the GELU table after the head), the same frame and trailer."""
    v1, v2 = image_layout.V1, image_layout.V2
    assert type(v1) is type(v2) and v1.table_at is None and v1.widths == (30,)
    assert image_layout.layout_for((30,)) is v1 and image_layout.layout_for((24,)) is v2
    assert image_layout.layout_for((30, 30)) is v2
    assert [(i, a.name) for i, a in v1.q_arrays_for()] == [(0, "w"), (0, "b"), (0, "g"), (0, "bb"), (None, "w_out"),
                                                           (None, "b_out"), (0, "gelu"), (None, "rsqrt_seed")]
    assert [a.name for _, a in v1.f32_arrays_for()] == [a.name for _, a in v2.f32_arrays_for((30,))]
    assert v1.q_payload_size() == v2.q_payload_size((30,)) and v1.trailer == v2.trailer
    assert v1.max_size == v1.image_size((30,)) == 3842 + 32
    assert [v1.header_name(f.name) for f in v1.record] == ["n_hidden", "h_bits", "e_bits", "fz", "fg", "fy", "eps_e",
                                                          "eps_m", "c30"]
    data = (EXAMPLE / "model.img").read_bytes()
    (rec,) = image_layout.layer_records(data, v1)
    assert rec["width"] == 30 and rec["c"] == image_layout.header_fields(data)["c30"]


@pytest.mark.parametrize("edit, match", [
    (lambda d: d[:-1], "disagree"), (lambda d: d[:10], "shorter"), (lambda d: b"XXXX" + d[4:], "magic"),
    (lambda d: d[:100] + bytes([d[100] ^ 1]) + d[101:], "CRC"),
])
def test_reader_refuses_corrupt_images(edit, match) -> None:
    data = (EXAMPLE / "model.img").read_bytes()
    with pytest.raises(ValueError, match=match):
        model_image.read_image(edit(data))


def test_reader_refuses_a_hash32_that_is_not_the_trailers() -> None:
    d = (EXAMPLE / "model.img").read_bytes()
    hash32 = image_layout.header_fields(d)["hash32"]
    with pytest.raises(ValueError, match="hash32"):
        model_image.read_image(image_layout.patch_header(d, hash32=hash32 ^ 1))


KEY = bytes(range(1, 33))


def test_signed_image_verifies_only_under_its_key() -> None:
    """An HMAC-signed image (flag 0x0002, tag after the trailer) reads back with its key, is refused under
    another key or when the tag is altered, and an unsigned image is refused when a key is required."""
    b = load_bundle(EXAMPLE)
    signed = model_image.image_bytes(b.qparams, b.fparams, b.content_hash, model_version=2, hmac_key=KEY)
    assert len(signed) == 3842 + 32 and image_layout.header_fields(signed)["flags"] == 0x0003
    assert model_image.read_image(signed, hmac_key=KEY).model_version == 2
    assert model_image.read_image(signed).model_version == 2  # no key: tag length-checked only
    # the same as signing the unsigned image afterwards
    unsigned = model_image.image_bytes(b.qparams, b.fparams, b.content_hash, model_version=2)
    assert model_image.sign_image(unsigned, KEY) == signed
    with pytest.raises(ValueError, match="does not verify"):
        model_image.read_image(signed, hmac_key=bytes(32))
    with pytest.raises(ValueError, match="does not verify"):
        model_image.read_image(signed[:-1] + bytes([signed[-1] ^ 1]), hmac_key=KEY)
    with pytest.raises(ValueError, match="no tag"):
        model_image.read_image(unsigned, hmac_key=KEY)
    with pytest.raises(ValueError, match="HMAC key of 3 bytes"):
        model_image.sign_image(unsigned, b"abc")
    with pytest.raises(ValueError, match="disagree"):
        model_image.read_image(signed[:-32])  # flag set, tag cut off


def test_c_layout_header_is_generated_from_the_one_description(tmp_path) -> None:
    """firmware_c/include/slipest_image_layout.h is what export/image_layout.py generates (run
    `python -m fleetlab.cli.image_layout_header` after changing the layout), the same text on every run, and its
    offsets are the Python writer's."""
    text = image_layout.c_header()
    assert text == image_layout.c_header()
    committed = REPO / "firmware_c" / "include" / "slipest_image_layout.h"
    assert committed.read_text(encoding="utf-8") == text, "regenerate: python -m fleetlab.cli.image_layout_header"
    out = tmp_path / "layout.h"
    res = subprocess.run([sys.executable, "-m", "fleetlab.cli.image_layout_header", str(out)], capture_output=True,
                         text=True)
    assert res.returncode == 0, res.stderr
    assert out.read_bytes() == committed.read_bytes()
    data = (EXAMPLE / "model.img").read_bytes()
    off = image_layout.CURRENT.offsets
    assert f"#define SLIPEST_IMAGE_OFF_FLAGS {off['flags']}u" in text and off["flags"] == 10
    assert f"#define SLIPEST_IMAGE_TRAILER_SIZE {model_image.TRAILER_SIZE}u" in text
    assert struct.unpack_from("<I", data, off["model_version"])[0] == model_image.read_image(data).model_version


def test_patch_header_names_fields_and_reseals() -> None:
    data = (EXAMPLE / "model.img").read_bytes()
    patched = image_layout.patch_header(data, model_version=9)
    assert model_image.read_image(patched).model_version == 9  # CRC resealed: every check passes
    assert image_layout.patch_header(patched, model_version=1) == data
    with pytest.raises(ValueError, match="no header field 'archh'"):
        image_layout.patch_header(data, archh=2)


# --- format 2: the layer table (issue 28 item 4) ---------------------------------------------------------------

def _net(hidden: tuple[int, ...], seed: int = 0):
    import torch

    from fleetlab.export import manifest
    from fleetlab.export.quant import FloatNet, quantize
    from fleetlab.models.mlp import SlipNet

    torch.manual_seed(seed)
    fn = FloatNet.from_model(SlipNet(hidden).eval())
    qn = quantize(fn)
    return qn, fn, manifest.content_hash(qn, fn)


@pytest.mark.parametrize("hidden", [(128, 64, 32), (24, 9), (2, 256, 3, 5), (24,)])
def test_format2_roundtrips_any_architecture(hidden) -> None:
    """A format-2 image carries the layer table: every block's arrays and shifts, the head and the float
    model read back unchanged, and its size is the one the layout computes for these widths."""
    qn, fn, h = _net(hidden)
    data = model_image.image_bytes(qn, fn, h, model_version=4)
    f = image_layout.header_fields(data)
    assert (f["format"], f["arch"], f["n_layers"]) == (2, image_layout.ARCH_TABLE, len(hidden))
    assert [r["width"] for r in image_layout.layer_records(data)] == list(hidden)
    assert len(data) == image_layout.V2.image_size(hidden, tag=False)
    img = model_image.read_image(data)
    assert img.format_version == 2 and img.model_version == 4 and img.content_hash == h
    assert model_image.same_model(img, qn) and img.fnet.hidden == hidden
    for a, b in zip(img.fnet.blocks, fn.blocks):
        assert all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ("w", "b", "gamma", "beta"))
    assert np.array_equal(img.fnet.w_out, fn.w_out) and img.fnet.eps == np.float32(fn.eps)
    # explicit little-endian: block 1's w[0][0] right after the header, low byte first
    assert struct.unpack_from("<h", data, image_layout.V2.header_size)[0] == int(qn.blocks[0].w[0, 0])
    q_only = model_image.image_bytes(qn, None, h)
    assert len(q_only) == image_layout.V2.image_size(hidden, f32=False, tag=False)
    assert model_image.read_image(q_only).fnet is None


def test_format2_signed_and_refusals() -> None:
    """The frame's checks hold for format 2 (HMAC, CRC, lengths), and the table is checked: a width that
    does not match the payload, a shift that is not the scheme's, a nonzero unused record."""
    qn, fn, h = _net((24, 9))
    data = model_image.image_bytes(qn, fn, h)
    signed = model_image.image_bytes(qn, fn, h, hmac_key=KEY)
    assert model_image.read_image(signed, hmac_key=KEY).content_hash == h
    with pytest.raises(ValueError, match="does not verify"):
        model_image.read_image(signed, hmac_key=bytes(32))
    with pytest.raises(ValueError, match="CRC"):
        model_image.read_image(data[:200] + bytes([data[200] ^ 1]) + data[201:])
    with pytest.raises(ValueError, match="disagree"):
        model_image.read_image(data[:-1])
    V2 = image_layout.V2
    rec = V2.table_at + V2.record_offsets["width"]
    fz = V2.table_at + V2.record_offsets["fz"]
    for at, value, match in ((rec, 25, "disagree"), (fz, data[fz] + 1, "not the scheme's"),
                             (V2.table_at + 3 * V2.record_size, 1, "reserved")):
        edited = bytearray(data)
        edited[at] = value
        with pytest.raises(ValueError, match=match):
            model_image.read_image(image_layout.reseal(bytes(edited)))
    with pytest.raises(ValueError, match="layer table of 5"):
        model_image.read_image(image_layout.patch_header(data, n_layers=5))


def test_unknown_format_is_refused_by_its_version() -> None:
    """A format this reader does not know is refused with an error that names the version."""
    data = (EXAMPLE / "model.img").read_bytes()
    with pytest.raises(ValueError, match="format version 3; this reader knows 1, 2"):
        model_image.read_image(image_layout.patch_header(data, format=3))


def test_c_size_formula_of_format2_is_the_layouts() -> None:
    """SLIPEST_IMAGE_V2_SIZE in the generated C header (it sizes the C reader's largest image from the build's
    caps) gives the size the Python layout computes, for SN-D and for an irregular shape."""
    import re

    text = image_layout.c_header()
    body = re.search(r"#define SLIPEST_IMAGE_V2_SIZE\(weights, units, blocks\) \\\n(.*?\))\n\n", text + "\n", re.S)
    assert body is not None
    expr = re.sub(r"(\d)u\b", r"\1", body[1].replace("\\\n", " "))
    for hidden in [(128, 64, 32), (24, 9), (256, 256, 256, 256)]:
        widths = (image_layout.N_IN,) + hidden
        weights = sum(a * b for a, b in zip(widths[1:], widths[:-1])) + image_layout.N_OUT * hidden[-1]
        size = eval(expr, {}, {"weights": weights, "units": sum(hidden) + 3, "blocks": len(hidden)})  # noqa: S307
        assert size == image_layout.V2.image_size(hidden), hidden
