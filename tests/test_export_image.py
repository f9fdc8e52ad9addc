"""model.img written by `fleetlab export`: the Python writer and reader round-trip, and the reader
refuses what the C reader refuses (the C reader itself: tests/test_firmware.py)."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from fleetlab.export import image_layout, model_image
from fleetlab.export.bundle import load_bundle

EXAMPLE = Path(__file__).resolve().parents[1] / "firmware_c" / "bundles" / "example"


def test_writer_reader_roundtrip() -> None:
    b = load_bundle(EXAMPLE)
    data = model_image.image_bytes(b.qparams, b.fparams, b.content_hash, model_version=5)
    assert len(data) == 3842 and data[:4] == b"SLPM"
    img = model_image.read_image(data)
    assert img.model_version == 5 and img.content_hash == b.content_hash
    for name, _, _ in model_image.Q_LAYOUT:
        assert np.array_equal(img.qparams_arrays[name], np.asarray(getattr(b.qparams, name))), name
    for name in ("w1", "b1", "gamma", "beta", "w2", "b2"):
        assert np.array_equal(getattr(img.fparams, name), getattr(b.fparams, name)), name
    assert img.scalars["fy"] == b.qparams.fy and img.scalars["eps_m"] == b.qparams.eps_m
    # explicit little-endian: w1[0][0] sits right after the header, low byte first, whatever the host's order
    assert struct.unpack_from("<h", data, image_layout.CURRENT.header_size)[0] == int(b.qparams.w1[0, 0])


def test_bundle_image_is_the_bundles_model() -> None:
    b = load_bundle(EXAMPLE)
    data = (EXAMPLE / "model.img").read_bytes()
    assert data == model_image.image_bytes(b.qparams, b.fparams, b.content_hash, b.manifest["model_version"])


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


def test_c_layout_header_is_generated_from_the_one_description() -> None:
    """firmware_c/include/slipest_image_layout.h is what export/image_layout.py generates (run
    `python -m fleetlab.export.image_layout c firmware_c/include/slipest_image_layout.h` after changing the
    layout), the same text on every run, and its offsets are the Python writer's."""
    text = image_layout.c_header()
    assert text == image_layout.c_header()
    assert image_layout.C_HEADER.read_text(encoding="utf-8") == text, "regenerate slipest_image_layout.h"
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
    from fleetlab.export.quant import FloatNet, quantize_net
    from fleetlab.models.mlp import SlipNet

    torch.manual_seed(seed)
    fn = FloatNet.from_model(SlipNet(hidden).eval())
    qn = quantize_net(fn)
    return qn, fn, manifest.content_hash_net(qn, fn)


@pytest.mark.parametrize("hidden", [(128, 64, 32), (24, 9), (2, 256, 3, 5)])
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
    assert model_image.same_model(img, qn) and img.fparams.hidden == hidden
    for a, b in zip(img.fparams.blocks, fn.blocks):
        assert all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ("w", "b", "gamma", "beta"))
    assert np.array_equal(img.fparams.w_out, fn.w_out) and img.fparams.eps == np.float32(fn.eps)
    # explicit little-endian: block 1's w[0][0] right after the header, low byte first
    assert struct.unpack_from("<h", data, image_layout.V2.header_size)[0] == int(qn.blocks[0].w[0, 0])
    q_only = model_image.image_bytes(qn, None, h)
    assert len(q_only) == image_layout.V2.image_size(hidden, f32=False, tag=False)
    assert model_image.read_image(q_only).fparams is None


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
