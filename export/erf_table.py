"""The float32 erf of the C float kernel: piecewise polynomials, written out as a C header.

The float path's exact GELU needs erf(y/sqrt 2) once per hidden unit. libm's erff costs about a hundred
instructions per call on the flight CPUs (more where it falls back to expf), and it dominated the float
inference on SPARC. The header made here evaluates erf on |x| < 4 with one table row per half-unit
interval and an 8-term Horner polynomial, with no division, no libm call and no data-dependent loop;
beyond 4, erf is 1 in float32. Each row is the Chebyshev interpolant of erf on its interval (a near-minimax
fit) in the offset from the row's centre. Row 0 is centred on 0 and has no constant term, so that erf(x)
keeps its relative accuracy for tiny x.

The coefficients are computed in 50-digit arithmetic (mpmath), never with numpy's least-squares fit: a
BLAS solve picks its kernel by CPU, and the last bit of a float32 coefficient then depends on the machine
(issue 26). The interpolant at N Chebyshev nodes has a closed form, a cosine sum per coefficient (the
discrete orthogonality of T_j on the nodes), so no solve is needed at all; the only rounding that reaches
the header is the final one to float32, the same on every machine.

    python -m fleetlab.cli.erf_table [--check]   (prints the header; --check prints the max error)

The committed header is `firmware_c/src/slipest_erf_f32.h`; tests/test_erf_table.py checks that it
equals this module's output and measures the float32 evaluation error against scipy's erf.
"""

from __future__ import annotations

import mpmath
import numpy as np
from scipy.special import erf

WIDTH = 0.5  # interval width (the kernel indexes rows by (int)(|x| * 2))
TOP = 4.0  # erf(4) = 1 - 1.5e-8 rounds to 1.0f: the table ends there
TERMS = 8  # Horner terms per row (degree 7)
_NODES = 256
_DIGITS = 50  # working precision of the fit: every coefficient is exact far below float32's last bit


def _interpolant(f, lo: float, hi: float, degree: int) -> list:
    """Monomial coefficients (lowest power first, mpf) of f's degree-`degree` Chebyshev interpolant on [lo, hi].

    The least-squares Chebyshev fit at _NODES Chebyshev points, in closed form: with s_k = cos(theta_k),
    theta_k = pi (k + 1/2) / N, c_j = (2 / N) sum_k f(t_k) cos(j theta_k) (c_0 halved). Then
    sum_j c_j T_j(s) is expanded into powers of s (T_j's integer coefficients) and s = (t - mid) / half into
    powers of t (binomial expansion). Pure mpmath arithmetic: the same digits on every CPU.
    """
    with mpmath.workdps(_DIGITS):
        n = _NODES
        mid, half = (mpmath.mpf(lo) + mpmath.mpf(hi)) / 2, (mpmath.mpf(hi) - mpmath.mpf(lo)) / 2
        theta = [mpmath.pi * (k + mpmath.mpf(1) / 2) / n for k in range(n)]
        fk = [f(mid + half * mpmath.cos(th)) for th in theta]
        cheb = [2 * mpmath.fsum(v * mpmath.cos(j * th) for v, th in zip(fk, theta)) / n for j in range(degree + 1)]
        cheb[0] /= 2
        # T_0 = 1, T_1 = s, T_{j+1} = 2 s T_j - T_{j-1}: integer power coefficients, exact
        t_prev, t_cur = [1], [0, 1]
        in_s = [mpmath.mpf(0)] * (degree + 1)
        for j in range(degree + 1):
            tj = t_prev if j == 0 else t_cur
            for i, a in enumerate(tj):
                in_s[i] += cheb[j] * a
            if j >= 1:
                t_prev, t_cur = t_cur, [-(t_prev[i] if i < len(t_prev) else 0) + (2 * t_cur[i - 1] if i >= 1 else 0)
                                        for i in range(len(t_cur) + 1)]
        # s^i = (t - mid)^i / half^i
        in_t = [mpmath.mpf(0)] * (degree + 1)
        for i, a in enumerate(in_s):
            for r in range(i + 1):
                in_t[r] += a * mpmath.binomial(i, r) * (-mid) ** (i - r) / half**i
        return in_t


def _f32(v) -> float:
    """A working-precision number rounded to float32 (through float64, like the float path always did)."""
    return float(np.float32(float(v)))


def rows() -> list[tuple[float, list[float]]]:
    """(centre, monomial coefficients in u = |x| - centre, lowest power first) per interval, float32-rounded."""
    out = []
    for k in range(int(TOP / WIDTH)):
        lo, hi = k * WIDTH, (k + 1) * WIDTH
        if k == 0:
            # erf(x) = x q(x): no constant term, so that erf keeps its relative accuracy for tiny x
            centre = 0.0
            mono = [0, *_interpolant(lambda x: mpmath.erf(x) / x, lo, hi, TERMS - 2)]
        else:
            centre = (lo + hi) / 2
            mono = _interpolant(lambda u, c=centre: mpmath.erf(c + u), lo - centre, hi - centre, TERMS - 1)
        out.append((_f32(centre), [_f32(v) for v in mono]))
    return out


def erf_f32(x: np.ndarray, table: list[tuple[float, list[float]]] | None = None) -> np.ndarray:
    """The C header's erf, step by step in float32 (the same operations in the same order)."""
    table = rows() if table is None else table
    x = np.asarray(x, dtype=np.float32)
    a = np.abs(x)
    r = np.ones_like(a)
    inside = a < np.float32(TOP)
    idx = (a[inside] * np.float32(1 / WIDTH)).astype(np.int32)
    cen = np.array([c for c, _ in table], dtype=np.float32)[idx]
    coef = np.array([m for _, m in table], dtype=np.float32)[idx]
    u = a[inside] - cen
    acc = coef[:, TERMS - 1]
    for j in range(TERMS - 2, -1, -1):
        acc = (acc * u + coef[:, j]).astype(np.float32)
    r[inside] = np.minimum(acc, np.float32(1.0))
    r[np.isnan(a)] = np.nan  # the C code returns a NaN argument unchanged
    return np.where(x < 0, -r, r).astype(np.float32)


def max_error(n: int = 2_000_001) -> float:
    """Largest |erf_f32(x) - erf(x)| over a dense grid of [-6, 6] (float32 evaluation, exact reference)."""
    x = np.linspace(-6.0, 6.0, n).astype(np.float32)
    return float(np.abs(erf_f32(x).astype(np.float64) - erf(x.astype(np.float64))).max())


def _lit(v: float) -> str:
    text = f"{v:.9g}"
    return (text if any(ch in text for ch in ".en") else text + ".0") + "f"


def header() -> str:
    """The C header text (committed as firmware_c/src/slipest_erf_f32.h)."""
    lines = [
        "/* erf for the float kernel's exact GELU: one 8-term polynomial per half-unit interval of |x| < 4.",
        " * GENERATED by `python -m fleetlab.cli.erf_table` (export/erf_table.py says how the rows are fitted);",
        " * do not edit. Max |error| against the exact erf, evaluated in float32: below 1e-7 (tests/test_erf_table.py).",
        " * Internal header of slipest_infer_f32.c: no libm call, no division, a fixed number of steps. */",
        "#ifndef SLIPEST_ERF_F32_H",
        "#define SLIPEST_ERF_F32_H",
        "",
        "static inline float slipest_erf_f32(float x)",
        "{",
        "    /* row k covers k/2 <= |x| < (k+1)/2: { centre, c0 .. c7 } of c0 + c1 u + ... + c7 u^7, u = |x| - centre */",
        f"    static const float rows[{int(TOP / WIDTH)}][{TERMS + 1}] = {{",
    ]
    for centre, mono in rows():
        lines.append("        {" + ", ".join(_lit(v) for v in [centre, *mono]) + "},")
    lines += [
        "    };",
        "    float a = (x < 0.0f) ? -x : x;",
        "    float r;",
        f"    if (a < {_lit(TOP)}) {{",
        f"        const float *c = rows[(int)(a * {_lit(1 / WIDTH)})]; /* a < {TOP:g}: row 0..{int(TOP / WIDTH) - 1} */",
        "        float u = a - c[0];",
        f"        r = c[{TERMS}];",
    ]
    lines += [f"        r = (r * u) + c[{j + 1}];" for j in range(TERMS - 2, -1, -1)]
    lines += [
        "        if (r > 1.0f) {",
        "            r = 1.0f;",
        "        }",
        f"    }} else if (a >= {_lit(TOP)}) {{",
        "        r = 1.0f;",
        "    } else {",
        "        r = x; /* NaN, returned as it came */",
        "    }",
        "    return (x < 0.0f) ? -r : r;",
        "}",
        "",
        "#endif",
        "",
    ]
    return "\n".join(lines)
