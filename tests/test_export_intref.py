"""The torch integer reference against an independent plain-Python-int implementation of the scheme.

`spec_infer` below is written from docs/fixed_point.md with Python integers (which never wrap) and
asserts at every step that the value fits the C type the kernel keeps it in; so the property tests
check both bit-exactness of export/intref.py and the overflow bounds of the scheme.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fleetlab.export import intref, sns_profile
from fleetlab.export.quant import FloatBlock, FloatNet, quantize, rsqrt_seed_table
from fleetlab.models import build

I32 = (-(2**31), 2**31 - 1)
U32 = (0, 2**32 - 1)
U64 = (0, 2**64 - 1)


def fits(v: int, rng: tuple[int, int], what: str) -> int:
    assert rng[0] <= v <= rng[1], f"{what} = {v} overflows [{rng[0]}, {rng[1]}]"
    return v


def rsr(x: int, k: int) -> int:
    return x if k == 0 else (x + (1 << (k - 1))) >> k


def spec_shifts(width: int) -> tuple[int, int, int, int]:
    """(h_bits, e_bits, fz, c) of a block of `width` units, from the rules of docs/fixed_point.md."""
    h_bits = min(24, 30 - math.ceil(math.log2(2 * width)))  # 2 H 2^h_bits <= 2^30
    e_bits = max(e for e in range(14) if width * 2 ** (2 * e) <= 2**31)
    fz = max(f for f in range(13) if math.sqrt(width) * 2**f * (1 + 2**-14) < 2**15 - 1)
    return h_bits, e_bits, fz, round(math.sqrt(width) * 2 ** (fz + 2))


def spec_block(blk, seed_table, x: list[int]) -> tuple[list[int], int]:
    """One Linear -> LayerNorm -> GELU block on int16 inputs: (g in Q(fy), saturations)."""
    width = blk.w.shape[0]
    h_bits, e_bits, fz, c = spec_shifts(width)
    assert (blk.h_bits, blk.e_bits, blk.fz, blk.c) == (h_bits, e_bits, fz, c)
    margin = 2 ** (32 - h_bits)  # room for the rounding term of rsr(h, k1)
    sat = 0
    w, b = blk.w.tolist(), blk.b.tolist()
    h = []
    for i in range(width):
        acc = b[i]
        for j in range(len(x)):
            acc = fits(acc + w[i][j] * x[j], (-(2**31) + margin, 2**31 - 1 - margin), "accumulator")
        h.append(acc)
    k1 = max(0, max(abs(v) for v in h).bit_length() - h_bits)
    hp = [fits(rsr(v, k1), (-(2**h_bits), 2**h_bits), "h'") for v in h]
    total = fits(sum(hp), (-(2**30), 2**30 - 1), "sum h'")  # the C kernel saturates it at 2^30
    d = [fits(width * v - total, (-(2**30), 2**30), "d") for v in hp]
    k2 = max(0, max(abs(v) for v in d).bit_length() - e_bits)
    e = [fits(rsr(v, k2), (-(2**e_bits), 2**e_bits), "e") for v in d]
    s = fits(sum(v * v for v in e), (0, 2**31), "sum e^2")
    t = blk.eps_e - 2 * (k1 + k2)
    if blk.eps_m == 0 or t <= -16:
        eps = 0
    elif t >= 16:
        eps, sat = 2**30, sat + 1
    elif t >= 0:
        eps = blk.eps_m << t
    else:
        eps = rsr(blk.eps_m, -t)
    v = fits(s + eps, U32, "variance + eps")
    if v == 0:
        mult = 0
    else:
        a = (32 - v.bit_length()) // 2
        wn = fits(v << (2 * a), U32, "normalised variance")
        assert 2**30 <= wn
        y = int(seed_table[(wn >> 27) - 8])
        for _ in range(2):
            y2 = fits(y * y, U64, "y^2") >> 30
            tt = fits((wn >> 2) * y2, U64, "w y^2") >> 30
            y = fits(y * (3 * 2**30 - tt), U64, "newton") >> 31
        mult = fits(((y * c) << a) + 2**31, (0, 2**63 - 1), "M (64-bit)") >> 32
        fits(mult, I32, "M")
    T = blk.gelu.astype(int).tolist()
    sh = blk.fy - 4
    out = []
    for i in range(width):
        z = rsr(fits(e[i] * mult, (-(2**31) + 2**15, 2**31 - 1 - 2**15), "e M"), 16)
        fits(z, (-(2**15) + 1, 2**15 - 1), "z")  # the proven bound that lets C skip a clamp here
        u = fits(rsr(fits(int(blk.g[i]) * z, I32, "gamma z"), fz + blk.fg - blk.fy) + int(blk.bb[i]), I32, "u")
        if not -32768 <= u <= 32767:
            u, sat = max(-32768, min(32767, u)), sat + 1
        vv = abs(u)
        k, f = vv >> sh, vv & ((1 << sh) - 1)
        tneg = 0 if k >= 128 else T[k] + rsr((T[k + 1] - T[k]) * f, sh)
        out.append(fits(max(u, 0) + tneg, (-(2**15), 2**15 - 1), "g (the next block's int16 input)"))
    return out, sat


def spec_infer(net, x: list[int]) -> tuple[list[int], int]:
    """One window, straight from the written scheme. Returns (logits, saturations)."""
    sat = 0
    for blk in net.blocks:
        x, s = spec_block(blk, net.rsqrt_seed, x)
        sat += s
    logits = net.b_out.astype(int).tolist()
    for c in range(len(logits)):
        for i, g in enumerate(x):
            logits[c] = fits(logits[c] + int(net.w_out[c, i]) * g, I32, "head accumulator")
    return logits, sat


def random_params(rng: np.random.Generator, scale: float) -> FloatNet:
    """A random SN-S (one block of 30 units)."""
    f = lambda *s: (rng.normal(size=s) * scale).astype(np.float32)  # noqa: E731
    blk = FloatBlock(w=f(30, 12), b=f(30), gamma=(1 + f(30)).astype(np.float32), beta=f(30) * 0.3)
    return FloatNet([blk], w_out=f(3, 30), b_out=f(3))


def random_inputs(rng: np.random.Generator, n: int) -> np.ndarray:
    """int16 features: a mix of small, typical and extreme values."""
    kind = rng.integers(0, 3, size=(n, 12))
    small = rng.integers(-50, 50, size=(n, 12))
    typical = rng.integers(-6000, 6000, size=(n, 12))
    extreme = rng.choice([-32768, 32767], size=(n, 12))
    return np.select([kind == 0, kind == 1], [small, typical], extreme).astype(np.int16)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31), scale=st.sampled_from([1e-3, 0.05, 0.5, 3.0, 40.0]))
def test_intref_equals_independent_spec(seed: int, scale: float) -> None:
    rng = np.random.default_rng(seed)
    qp = quantize(random_params(rng, scale))
    x = random_inputs(rng, 6)
    x[0] = 0
    logits, sat = intref.run(qp, x)
    for row in range(len(x)):
        want, want_sat = spec_infer(qp, x[row].astype(int).tolist())
        assert logits[row].tolist() == want
        assert sat[row] == want_sat


def test_worst_case_inputs_cannot_overflow() -> None:
    """Inputs at the int16 extremes that maximise every layer-1 accumulator, on models with large
    weights and biases: every intermediate stays inside its C type (checked by spec_infer)."""
    rng = np.random.default_rng(7)
    for scale in (0.01, 1.0, 100.0):
        fp = random_params(rng, scale)
        fp.blocks[0].b = (np.sign(fp.blocks[0].b) * 1e4).astype(np.float32)  # biases that force the bias limit
        qp = quantize(fp)
        sc = sns_profile.scalars(qp)
        assert sc["acc1_bound"] <= 2**31 - 1 - 2**8 and sc["acc2_bound"] <= 2**31 - 1
        w1, b1 = qp.blocks[0].w, qp.blocks[0].b
        rows = []
        for i in range(30):
            s = np.where(w1[i] >= 0, 1, -1)
            rows += [np.where(s > 0, 32767, -32768), np.where(s > 0, -32768, 32767)]
        x = np.array(rows, dtype=np.int16)
        logits, _ = intref.run(qp, x)
        for row in range(0, len(x), 7):
            assert spec_infer(qp, x[row].astype(int).tolist())[0] == logits[row].tolist()
        h = x.astype(np.int64) @ w1.T.astype(np.int64) + b1
        assert np.abs(h).max() <= 2**31 - 1


def _model_params(seed: int = 3) -> FloatNet:
    return FloatNet.from_model(build("sn-s", seed=seed).eval())


def test_saturation_is_counted() -> None:
    """A Q(FY) chosen too fine makes u leave int16: the reference and the spec count the same events."""
    qp = quantize(_model_params())
    blk = qp.blocks[0]
    blk.fy = 12
    blk.bb = np.full(30, 30000, np.int32)  # beta ~ 7.3 in Q12 ...
    blk.g = np.full(30, 32767, np.int16)  # ... + gamma ~ 2 at FG = 14: any z > 0.34 leaves int16
    blk.fg = 14
    x = random_inputs(np.random.default_rng(1), 50)
    logits, sat = intref.run(qp, x)
    assert sat.sum() > 0
    for row in range(0, 50, 5):
        want, want_sat = spec_infer(qp, x[row].astype(int).tolist())
        assert (logits[row].tolist(), int(sat[row])) == (want, want_sat)


def test_eps_cap_counts_a_saturation() -> None:
    """When eps dominates (near-constant hidden layer), eps is capped at 2^30 and counted once."""
    qp = quantize(_model_params())
    blk = qp.blocks[0]
    blk.w = np.zeros_like(blk.w)
    blk.b = np.full(30, 5, np.int32)  # constant layer: variance 0, k1 = k2 = 0
    blk.eps_m, blk.eps_e = 2**14, 20
    logits, sat = intref.run(qp, np.zeros((1, 12), np.int16))
    assert sat.tolist() == [1]
    assert spec_infer(qp, [0] * 12) == (logits[0].tolist(), 1)


def test_rsqrt_matches_float_and_stays_bounded() -> None:
    """M = sqrt(30) 2^28 / sqrt(v) to 1e-5 relative + 1/2 over the whole uint32 range (sampled + edges)."""
    qp = quantize(_model_params())
    net = intref.IntSlipNet(qp).blocks[0]
    v = np.unique(np.concatenate([
        np.random.default_rng(0).integers(1, 2**32 - 1, 200_000, dtype=np.int64),
        2 ** np.arange(32, dtype=np.int64), 2 ** np.arange(1, 33, dtype=np.int64) - 1,
        [3 * 2**30, 2**31 + 2**30 - 1],
    ]))
    m = net.rsqrt_mult(torch.from_numpy(v).unsqueeze(1)).squeeze(1).numpy().astype(np.float64)
    exact = math.sqrt(30) * 2**28 / np.sqrt(v.astype(np.float64))
    assert (np.abs(m - exact) <= 1e-5 * exact + 0.5).all()  # Newton error + one rounding
    assert m.max() <= 2**31 - 1
    assert int(net.rsqrt_mult(torch.zeros(1, 1, dtype=torch.int64))) == 0
    assert np.array_equal(rsqrt_seed_table(), qp.rsqrt_seed)


def test_fixed_point_follows_float_on_random_model() -> None:
    """On an untrained SN-S and typical inputs the integer logits track the float ones."""
    model = build("sn-s", seed=11).eval()
    qp = quantize(FloatNet.from_model(model))
    rng = np.random.default_rng(2)
    xq = rng.integers(-3000, 3000, size=(500, 12)).astype(np.int16)
    from fleetlab.data.features_int import FEATURE_LSB

    with torch.no_grad():
        fl = model(torch.from_numpy((xq * FEATURE_LSB).astype(np.float32))).numpy()
    ql = intref.run(qp, xq)[0] / qp.logit_scale
    assert np.abs(ql - fl).max() < 0.02


def test_refuses_non_int16_inputs() -> None:
    qp = quantize(_model_params())
    with pytest.raises(ValueError, match="int16"):
        intref.IntSlipNet(qp)(torch.full((1, 12), 40000, dtype=torch.int64))


# --- any architecture within the caps (issue 28) -------------------------------------------------

def random_net(rng: np.random.Generator, hidden: tuple[int, ...], scale: float) -> FloatNet:
    f = lambda *s: (rng.normal(size=s) * scale).astype(np.float32)  # noqa: E731
    ln = lambda h: (rng.normal(size=h) * min(scale, 2.0)).astype(np.float32)  # noqa: E731  LayerNorm affine
    blocks, n_in = [], 12  # (a LayerNorm output beyond 2^15 / 2^4 cannot be exported at all: quant.py)
    for h in hidden:
        blocks.append(FloatBlock(w=f(h, n_in), b=f(h), gamma=(1 + ln(h)).astype(np.float32), beta=ln(h) * 0.3))
        n_in = h
    return FloatNet(blocks, f(3, n_in), f(3))


widths = st.one_of(st.integers(2, 40), st.sampled_from([2, 3, 31, 32, 33, 64, 127, 128, 255, 256]))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31), hidden=st.lists(widths, min_size=1, max_size=4).map(tuple),
       scale=st.sampled_from([1e-3, 0.05, 0.5, 3.0, 40.0]))
def test_any_architecture_intref_equals_spec(seed: int, hidden: tuple[int, ...], scale: float) -> None:
    """Random architectures within the caps, random models, random int16 inputs (a third at the rails):
    the torch reference equals the specification, and spec_block asserts every intermediate's C type."""
    rng = np.random.default_rng(seed)
    net = quantize(random_net(rng, hidden, scale))
    assert net.hidden == hidden
    x = random_inputs(rng, 3)
    x[0] = 0
    logits, sat = intref.run(net, x)
    for row in range(len(x)):
        assert (logits[row].tolist(), int(sat[row])) == spec_infer(net, x[row].astype(int).tolist())


@pytest.mark.parametrize("hidden", [(256, 256, 256, 256), (2, 2), (128, 64, 32), (24, 9)])
def test_caps_worst_case_inputs_cannot_overflow(hidden) -> None:
    """Widths at the caps with huge weights and biases, inputs at the int16 rails with the signs of
    block 1's rows: every intermediate of every block stays inside its C type."""
    rng = np.random.default_rng(5)
    fn = random_net(rng, hidden, 100.0)
    fn.blocks[0].b = (np.sign(fn.blocks[0].b) * 1e4).astype(np.float32)
    net = quantize(fn)
    w = net.blocks[0].w
    rows = [np.where(w[i] >= 0, 32767, -32768) for i in range(0, w.shape[0], max(1, w.shape[0] // 4))]
    x = np.array(rows + [-r - 1 for r in rows], dtype=np.int16)
    logits, sat = intref.run(net, x)
    for row in range(len(x)):
        assert (logits[row].tolist(), int(sat[row])) == spec_infer(net, x[row].astype(int).tolist())


def test_block_shifts_keep_sn_s_constants_and_shrink_with_width() -> None:
    from fleetlab.export import quant

    assert (quant.h_bits_of(30), quant.e_bits_of(30), quant.fz_of(30), quant.c_of(30)) == (24, 13, 12, quant.C30)
    assert quant.acc_limit_of(30) == quant.ACC1_LIMIT and quant.z_bound_of(30) == 5.5
    assert (quant.h_bits_of(256), quant.e_bits_of(256), quant.fz_of(256)) == (21, 11, 10)
    for h in range(2, 257):
        assert 2 * h * 2 ** quant.h_bits_of(h) <= 2**30 and h * 4 ** quant.e_bits_of(h) <= 2**31
        assert math.sqrt(h) * 2 ** quant.fz_of(h) < 2**15 - 1 and quant.c_of(h) < 2**17


def test_fixed_point_follows_float_on_a_deep_random_model() -> None:
    """SN-D and 24,9, untrained, typical inputs: the integer logits track the float ones."""
    from fleetlab.data.features_int import FEATURE_LSB

    for arch in ("sn-d", "24,9"):
        model = build(arch, seed=11).eval()
        net = quantize(FloatNet.from_model(model))
        xq = np.random.default_rng(2).integers(-3000, 3000, size=(500, 12)).astype(np.int16)
        with torch.no_grad():
            fl = model(torch.from_numpy((xq * FEATURE_LSB).astype(np.float32))).numpy()
        ql = intref.run(net, xq)[0] / net.logit_scale
        assert np.abs(ql - fl).max() < 0.03, arch
        assert (ql.argmax(1) == fl.argmax(1)).mean() > 0.99, arch
