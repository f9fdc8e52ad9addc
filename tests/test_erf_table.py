"""The float kernel's erf table (firmware_c/src/slipest_erf_f32.h) is the generator's output, and its
float32 evaluation stays within 1e-7 of the exact erf; a perturbed table is caught by the same measure."""

import numpy as np
from scipy.special import erf

from fleetlab.export import erf_table
from fleetlab.paths import repo_root

HEADER = repo_root() / "firmware_c" / "src" / "slipest_erf_f32.h"


def test_committed_header_is_generated():
    assert HEADER.read_text() == erf_table.header(), "regenerate: python -m fleetlab.cli.erf_table > " + str(HEADER)


def test_float32_error_below_1e7():
    assert erf_table.max_error() < 1e-7


def test_error_measure_catches_a_wrong_coefficient():
    table = erf_table.rows()
    centre, mono = table[3]
    table[3] = (centre, [mono[0], mono[1] * (1 + 1e-5), *mono[2:]])
    x = np.linspace(1.5, 2.0, 10001, dtype=np.float32)
    assert np.abs(erf_table.erf_f32(x, table) - erf(x.astype(np.float64))).max() > 1e-7


def test_special_values():
    x = np.array([0.0, -0.0, 4.0, -7.5, np.inf, -np.inf, np.nan], dtype=np.float32)
    got = erf_table.erf_f32(x)
    assert list(got[:6]) == [0.0, 0.0, 1.0, -1.0, 1.0, -1.0] and np.isnan(got[6])
