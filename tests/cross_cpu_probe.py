"""What tests/test_other_cpus.py runs inside one process started as another x86-64 CPU (QEMU user mode).

    python tests/cross_cpu_probe.py OUTDIR [--exports-only]

1. The generators whose output must be the same bytes on every machine (the erf table; the export of fixed
   weights: headers, model image, ONNX, the integer columns of the vectors) write into OUTDIR, for the test
   to compare with this machine's.
2. The checks that must hold on each machine by itself (docs/architecture.md, "Same bits where"): a fitness
   call's numbers in pieces of any size and with kept buffers, sharing of one call's rows among ants, a search
   repeated with the same seed, R lockstep runs equal to each run alone. They are the suite's own tests,
   selected by keyword, run here by pytest in this process (a child process would run natively).
   OUTDIR/checks.txt gets pytest's exit status and its summary. With --exports-only (the run on the
   test's own CPU, where the suite runs these checks anyway) only part 1 is done.
"""

from __future__ import annotations

import contextlib
import io
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ONE_MACHINE_CHECKS = [
    str(HERE / "test_acomerge.py"), str(HERE / "test_lockstep.py"),
    "-k", "fitness and not time and not rejects or deterministic_for_a_seed or batched_runs_equal "
          "or go_through_the_reference or row_of_one_call",
]


def main() -> int:
    out = Path(sys.argv[1])
    sys.path.insert(0, str(HERE))
    import generate_artifacts
    import pytest

    for name in ("erf", "bundle"):
        (out / name).mkdir(parents=True, exist_ok=True)
        with contextlib.redirect_stderr(io.StringIO()):  # the export's progress bar
            generate_artifacts.GENERATORS[name](out / name)
    if "--exports-only" in sys.argv[2:]:
        return 0
    log = io.StringIO()
    with contextlib.redirect_stdout(log):
        status = pytest.main(["-q", "-p", "no:cacheprovider", "-o", "addopts=", *ONE_MACHINE_CHECKS])
    tail = "\n".join(log.getvalue().strip().splitlines()[-15:])
    (out / "checks.txt").write_text(f"{int(status)}\n{tail}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
