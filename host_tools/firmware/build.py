"""The one CMake/QEMU driver: configure and build firmware_c for the host or a CPU target, run an
image under QEMU, run ctest.

The QEMU command line is not written here: the cross build records it (from the target file) in
`<build dir>/slipest_target.json`, and `run_image` reads it from there.
"""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from fleetlab.system_tools import need
from fleetlab.paths import repo_root
from .targets import Target, get
from fleetlab.errors import InputError


def _target(target: Target | str | None) -> Target | None:
    return get(target) if isinstance(target, str) else target


def configure_command(build_dir: Path, bundle: Path | None = None, *, target: Target | str | None = None,
                      options: dict[str, str] | None = None) -> list[str]:
    """argv of the CMake configure step (host build when target is None)."""
    cmd = ["cmake", "-S", str(repo_root()), "-B", str(build_dir), "-DCMAKE_BUILD_TYPE=Release",
           f"-DPython3_EXECUTABLE={sys.executable}"]
    if bundle is not None:
        cmd.append(f"-DSLIPEST_BUNDLE={Path(bundle).resolve()}")
    t = _target(target)
    if t is not None:
        cmd.append(f"-DCMAKE_TOOLCHAIN_FILE={t.toolchain_file}")
    cmd += [f"-D{k}={v}" for k, v in (options or {}).items()]
    return cmd


def build_command(build_dir: Path, jobs: int = 2, targets: tuple[str, ...] = ()) -> list[str]:
    cmd = ["cmake", "--build", str(build_dir), f"-j{jobs}"]
    return cmd + (["--target", *targets] if targets else [])


def ctest_command(build_dir: Path, regex: str | None = None) -> list[str]:
    return ["ctest", "--test-dir", str(build_dir), "--output-on-failure", "-V", *(["-R", regex] if regex else [])]


@dataclass
class Result:
    """A finished command: its argv (as strings), exit code and output."""
    cmd: list[str]
    returncode: int
    stdout: str
    stderr: str


def execute(cmd: list, *, timeout: float, cwd: Path | None = None) -> Result:
    """The one place a tool is run: output captured as text, never raises on a non-zero exit."""
    argv = [str(c) for c in cmd]
    proc = subprocess.run(argv, capture_output=True, text=True, cwd=cwd, timeout=timeout)
    return Result(argv, proc.returncode, proc.stdout, proc.stderr)


def run(cmd: list[str], *, timeout: float = 600, merge_stderr: bool = False, check: bool = True,
        what: str = "command") -> str:
    """Output of a build step (stdout, or stdout + stderr); OSError naming `what` if it fails."""
    res = execute(cmd, timeout=timeout)
    if check and res.returncode != 0:
        raise OSError(f"{what} failed ({res.returncode}): {' '.join(res.cmd)}\n"
                      f"{res.stdout[-2000:]}{res.stderr[-2000:]}")
    return res.stdout + res.stderr if merge_stderr else res.stdout


def cmake_build(build_dir: Path, bundle: Path | None = None, *, target: Target | str | None = None,
                options: dict[str, str] | None = None, jobs: int = 2, targets: tuple[str, ...] = ()) -> Path:
    """Configure and build firmware_c into build_dir (host, or cross for `target`); returns build_dir."""
    build_dir = Path(build_dir)
    need("cmake", "building the C estimator")
    t = _target(target)
    if t is not None:
        t.need_tools(f"the build for CPU target {t.name}")
    run(configure_command(build_dir, bundle, target=target, options=options), what="cmake configure")
    run(build_command(build_dir, jobs, targets), what="cmake build")
    return build_dir


def run_record(build_dir: Path) -> dict:
    """The cross build's record of how its images run (written by firmware_c/cmake/target.cmake)."""
    path = Path(build_dir) / "slipest_target.json"
    if not path.is_file():
        raise OSError(f"{build_dir}: no slipest_target.json (not a cross build of firmware_c?)")
    return json.loads(path.read_text())


def qemu_command(build_dir: Path, image: Path, *, icount: bool = False, trace: Path | None = None) -> list[str]:
    """QEMU argv for `image`; icount adds the target's counting options (system mode: -icount; user
    mode: a one-instruction-per-block exec trace written to `trace`)."""
    rec = run_record(build_dir)
    if not rec["run"] or not Path(rec["run"][0]).is_absolute():
        raise OSError(f"{build_dir}: QEMU for target {rec['name']} was not found at configure time")
    cmd = [str(image) if a == "@IMAGE@" else a for a in rec["run"]]
    if icount:
        if not rec["icount"]:
            raise OSError(f"target {rec['name']}: no instruction counting mode (user-mode QEMU)")
        extra = [str(trace) if a == "@TRACE@" else a for a in rec["icount"]]
        if "@TRACE@" in rec["icount"] and trace is None:
            raise InputError(f"target {rec['name']} counts by exec trace: pass trace=<log file>")
        cmd = cmd[:1] + extra + cmd[1:]
    return cmd


def run_image(build_dir: Path, image: str | Path, *, icount: bool = False, trace: Path | None = None,
              timeout: float = 300) -> str:
    """Run one image of a cross build under QEMU; stdout and stderr (semihosting console) together."""
    image = Path(build_dir) / image if not Path(image).is_absolute() else Path(image)
    return run(qemu_command(build_dir, image, icount=icount, trace=trace), timeout=timeout, merge_stderr=True,
               what="QEMU run")


def ctest(build_dir: Path, regex: str | None = None, timeout: float = 900) -> str:
    """ctest output (verbose); OSError if a test fails."""
    return run(ctest_command(build_dir, regex), timeout=timeout, what="ctest")
