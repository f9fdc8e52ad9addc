"""Frama-C EVA on the layer-table fixed-point kernel at the build's caps (issue 28) at the default
precision 5: opt-in, as one run takes minutes, longer than the test suite's budget allows (the suite runs
the same analysis and control at precision 3, about 30 s each: tests/test_export_arch.py).

    python scripts/eva_at_caps.py [--out DIR] [--no-control]

Exports a model of SLIPEST_MAX_LAYERS blocks of SLIPEST_MAX_WIDTH units (4 x 256 at the default caps;
random weights: the analysis covers every int16 input, and the export scales any weights to the proof's
bounds), runs EVA's `eva_infer_q` entry on it and prints the alarms (none expected), then the negative
control: the same analysis with the clamp of e removed from a copy of the kernel, where EVA must report
the overflow of e * e. Exit status 0 when both hold, 1 otherwise. docs/assurance.md records its output.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

CAPS = "256,256,256,256"  # SLIPEST_MAX_LAYERS x SLIPEST_MAX_WIDTH (firmware_c/include/slipest_model.h)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, default=None, help="where the caps bundle goes (default: a temporary folder)")
    p.add_argument("--no-control", action="store_true", help="skip the negative control (one EVA run less)")
    args = p.parse_args(argv)

    from fleetlab.assurance import analysers
    from fleetlab.export.bundle import export_bundle
    from fleetlab.export.vectors import draw_inputs
    from fleetlab.models import build

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    # the one way the analysers' negative controls copy the sources, and the line this one plants into
    from planted import LAYER_E_CLAMP, LAYER_E_UNCLAMPED, planted_src

    with tempfile.TemporaryDirectory() as tmp:
        bundle = args.out or Path(tmp) / "caps"
        export_bundle(build(CAPS, seed=0), bundle, inputs=draw_inputs(200, None, seed=3))
        t0 = time.perf_counter()
        (res,) = analysers.frama_c_eva(bundle, entries=["eva_infer_q"])
        reached = "Frama_C_show_each_class: {0; 1; 2}" in res.log
        print(f"eva_infer_q at the caps ({CAPS}): {len(res.alarms)} alarms, "
              f"{'reached' if reached else 'did NOT reach'} the class output ({time.perf_counter() - t0:.0f} s)")
        for a in res.alarms:
            print("  " + a)
        ok = reached and not res.alarms
        if not args.no_control:
            src = planted_src(Path(tmp), "slipest_infer_table_q.c", LAYER_E_CLAMP, LAYER_E_UNCLAMPED)
            t0 = time.perf_counter()
            (ctl,) = analysers.frama_c_eva(bundle, entries=["eva_infer_q"], src_dir=src)
            found = any("e_ * e_" in a for a in ctl.alarms)
            print(f"control, the clamp of e removed: {len(ctl.alarms)} alarms, e_ * e_ "
                  f"{'reported' if found else 'NOT reported'} ({time.perf_counter() - t0:.0f} s)")
            ok = ok and found
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
