"""What the assurance tools look at: the library's C files found by glob, the generated
CAN codec, include paths, and helpers that run tools (one, keeping its output; several at once)."""
from __future__ import annotations

import re
import subprocess
import sys
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import TypeVar

from fleetlab.host_tools.firmware.build import Result, execute

from ..compute import usable_cores
from ..errors import FleetlabError
from ..paths import default_bundle, repo_root
from .. import system_tools

# sources that use float on purpose (the f32 reference path); the fixed-point library omits them
FLOAT_SOURCES = ("slipest_features_f32.c", "slipest_infer_f32.c")
# sources CMake compiles only with the layer table (SLIPEST_LAYER_TABLE): the format-2 image visitor and the
# layer-table kernel
LAYER_TABLE_SOURCES = ("slipest_image_table.c", "slipest_infer_table_q.c")
T = TypeVar("T")


def fw() -> Path:
    """firmware_c/ of the C source tree (the clone, or the wheel's copy)."""
    return repo_root() / "firmware_c"


def library_sources(include_float: bool = True) -> list[Path]:
    files = sorted((fw() / "src").glob("*.c"))
    if not include_float:
        files = [f for f in files if f.name not in FLOAT_SOURCES]
    return files


def public_headers() -> list[Path]:
    return sorted((fw() / "include").glob("*.h"))


def generate_dbc(out_dir: Path, bundle: Path | None = None) -> Path:
    """cantools C codec from the repo DBC, integer-only: the CMake build's own generation script; beside it
    the CANopen object dictionary tables (slipest_co_od.h/.c) and the bundle's sha256 header
    (slipest_bundle_sha256.h; default: the example bundle), as CMake generates them."""
    tree = repo_root()
    run(["cmake", f"-DPYTHON={sys.executable}", f"-DDBC={tree / 'dbc' / 'slipest.dbc'}", f"-DGEN={out_dir}", "-P",
         tree / "firmware_c" / "cmake" / "generate_dbc.cmake"], check=True)
    run([sys.executable, str(tree / "canopen_od" / "generate.py"), "c", str(out_dir)], check=True)
    run(["cmake", f"-DBUNDLE={Path(bundle or default_bundle())}", f"-DOUT={out_dir / 'slipest_bundle_sha256.h'}",
         "-P", tree / "firmware_c" / "cmake" / "bundle_sha256.cmake"], check=True)
    return out_dir / "slipest_dbc.c"


def include_dirs(bundle: Path | None, gen_dir: Path) -> list[Path]:
    """The library's public headers, the bundle's (default: the example bundle), the generated codec."""
    return [fw() / "include", Path(bundle or default_bundle()), gen_dir]


def need(tool: str) -> str:
    """Path of `tool`, or errors.MissingTool naming `fleetlab assure` and the tool's Debian package."""
    return system_tools.need(tool, "fleetlab assure")


class ToolFailed(FleetlabError):
    """A tool an assurance check runs failed (a build, ctest, gcovr, cppcheck, Frama-C): the message is one line
    (the command and the line of its output that says why), `output` the tail of what it printed. `fleetlab
    assure CHECK` prints the line; the report records the check as failed, with the output, and keeps the others."""

    def __init__(self, message: str, output: str = ""):
        super().__init__(message)
        self.output = output


_ERROR_LINE = re.compile(r"\b(error|failed|fatal)\b", re.I)


def gist(*texts: str) -> str:
    """The one line of a tool's output that says why it failed: the first line naming an error, else the last
    non-empty line; the texts are searched in the order given (stderr first, then stdout)."""
    outputs = [[l.strip() for l in (t or "").splitlines() if l.strip()] for t in texts]
    hit = next((l for lines in outputs for l in lines if _ERROR_LINE.search(l)), None)
    line = hit or next((lines[-1] for lines in outputs if lines), "no output")
    return line if len(line) <= 300 else line[:300] + " …"


def command_name(cmd: Sequence) -> str:
    """How a failure names its command: the program, `python -m MODULE` for a module, cmake's step."""
    argv = [str(c) for c in cmd]
    name = Path(argv[0]).name
    if name.startswith("python") and len(argv) > 2 and argv[1] == "-m":
        return argv[2]
    if name == "cmake":
        return "cmake --build" if "--build" in argv else ("cmake -P " + Path(argv[-1]).name if "-P" in argv
                                                          else "cmake configure")
    return name


def run(cmd: list[str], *, check: bool = False, cwd: Path | None = None, timeout: float = 1800) -> Result:
    """A tool's full result (the analysers read exit codes and both streams); with check, ToolFailed (one line:
    the command and why) on a non-zero exit. Runs through the firmware driver's `execute`, like every build step."""
    try:
        res = execute(cmd, timeout=timeout, cwd=cwd)
    except subprocess.TimeoutExpired as e:
        raise ToolFailed(f"{command_name(cmd)} ran past its {timeout:.0f} s limit") from e
    if check and res.returncode != 0:
        raise ToolFailed(f"{command_name(cmd)} exited {res.returncode}: {gist(res.stderr, res.stdout)}",
                         f"{res.stdout[-3000:]}\n{res.stderr[-3000:]}".strip())
    return res


def concurrently(calls: Sequence[Callable[[], T]]) -> list[T]:
    """The results of `calls`, in their order, run on as many threads as this process has cores. Each call
    spends its time waiting for a tool's subprocess (the GIL is free meanwhile), so one report's checks or
    EVA's entries overlap; an exception is raised after every call has ended."""
    cores = usable_cores()
    if min(cores, len(calls)) <= 1:
        return [call() for call in calls]
    with ThreadPoolExecutor(min(cores, len(calls))) as pool:
        futures = [pool.submit(call) for call in calls]
        return [f.result() for f in futures]


def rel(path: str | Path, gen_dir: Path | None = None) -> str:
    """Stable display name: repo-relative, the generated codec as generated/<name>, a bundle file as bundle/<name>."""
    p = Path(path).resolve()
    if gen_dir is not None and p.parent == Path(gen_dir).resolve():
        return f"generated/{p.name}"
    if (p.parent / "manifest.json").is_file():  # any export bundle, wherever it lives (the demo's is in demo_out/)
        return f"bundle/{p.name}"
    try:
        r = p.relative_to(repo_root())
    except ValueError:
        return f"bundle/{p.name}"
    if r.parts[:2] == ("firmware_c", "bundles"):
        return f"bundle/{p.name}"
    return str(r)


def tool_version(cmd: list[str]) -> str:
    try:
        res = run(cmd, timeout=60)
    except OSError:
        return "not installed"
    except ToolFailed:
        return "did not answer"
    text = (res.stdout or res.stderr).strip().splitlines()
    return text[0] if text else "unknown"
