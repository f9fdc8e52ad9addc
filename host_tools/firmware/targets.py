"""CPU targets, discovered from their files.

A target is one CMake toolchain file under `firmware_c/cmake/` (or a directory named in
`$FLEETLAB_TARGET_DIRS`, `os.pathsep`-separated) that records what it is in
`set(SLIPEST_TARGET_<KEY> value)` lines: CMake uses the same lines for the build, so the file is the
only place a CPU is described. Files without a `SLIPEST_TARGET_NAME` line (shared toolchain parts,
scripts) are not targets.
"""

from __future__ import annotations

import os
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

from fleetlab.errors import FleetlabError
from fleetlab.system_tools import need
from fleetlab.paths import repo_root

ENV_DIRS = "FLEETLAB_TARGET_DIRS"
_SET = re.compile(r"^\s*set\(\s*SLIPEST_TARGET_([A-Z_]+)\s+(.*?)\s*\)\s*(?:#.*)?$", re.M)
REQUIRED = ("NAME", "DESCRIPTION", "COMPILER", "ENDIAN", "FPU", "INTEGER_ONLY", "QEMU", "QEMU_MODE", "REPORT", "VECTORS",
            "COUNTER")


class TargetError(FleetlabError, ValueError):
    """A target file that cannot be read as a target record."""


def _on(value: str) -> bool:
    return value.upper() in ("ON", "YES", "TRUE", "1")


@dataclass(frozen=True)
class Target:
    name: str
    description: str
    file: Path
    compiler: str  # C cross compiler executable
    endian: str  # "little" | "big"
    fpu: bool
    integer_only: bool  # only the fixed-point library is built and run
    qemu: str  # emulator executable
    qemu_mode: str  # "system" (bare metal) | "user" (static Linux image)
    qemu_machine: str  # board in system mode; "none" in user mode
    qemu_cpu: str
    report: str  # how the image reports: "semihosting" | "stdio" | "uart" (bare metal, QEMU serial on stdio)
    vectors: str  # how it gets vectors.bin: "semihosting" | "file" | "embed"
    counter: str  # instruction counter of the cost image: "systick" | "instret" | "trace" | "none"
    reference: bool = False  # the target whose figures are quoted first (bench c's <key>_* figures, the demo)
    cpu_flags: tuple[str, ...] = ()  # SLIPEST_CPU_FLAGS: the compiler's CPU/FPU/ABI options (stack analysis reuses them)
    unaligned_trap: bool = False  # the core can trap unaligned access (ARMv7-M): -DSLIPEST_TRAP_UNALIGNED=ON builds for it

    @property
    def toolchain_file(self) -> Path:
        return self.file

    @property
    def runs(self) -> bool:
        """False for a link-only target (SLIPEST_TARGET_QEMU none): built, never run."""
        return self.qemu != "none"

    @property
    def tools(self) -> tuple[str, ...]:
        """Executables a build and run of this target need (compiler, emulator)."""
        return (self.compiler, self.qemu) if self.runs else (self.compiler,)

    def need_tools(self, needed_for: str) -> None:
        """errors.MissingTool, naming `needed_for` and the tool's Debian package, if a tool is not on PATH."""
        for tool in self.tools:
            need(tool, needed_for)

    @property
    def emulator(self) -> str:
        """How the target runs, for reports: "QEMU <machine>" (system mode) or "<qemu binary> user mode"."""
        if not self.runs:
            return "no emulator (link only)"
        if self.qemu_mode == "system":
            return f"QEMU {self.qemu_machine}"
        return f"{self.qemu} user mode"

    @property
    def key(self) -> str:
        """Short name in figure keys: the name without its "cortex-" family word, "-" as "_" (cortex-m4: m4)."""
        return self.name.removeprefix("cortex-").replace("-", "_")

    @property
    def label(self) -> str:
        return f"{self.description} under {self.emulator}"

    def as_dict(self) -> dict:
        return {"name": self.name, "description": self.description, "file": str(self.file),
                "compiler": self.compiler, "reference": self.reference, "endian": self.endian,
                "fpu": self.fpu, "integer_only": self.integer_only, "qemu": self.qemu, "qemu_mode": self.qemu_mode,
                "qemu_machine": self.qemu_machine, "qemu_cpu": self.qemu_cpu, "report": self.report,
                "vectors": self.vectors, "counter": self.counter, "unaligned_trap": self.unaligned_trap}


_CPU_FLAGS = re.compile(r'^set\(SLIPEST_CPU_FLAGS\s+"([^"]*)"\)', re.M)


def parse_target_file(path: Path) -> Target | None:
    """The target recorded in `path`, or None if it records none; TargetError if the record is broken."""
    fields: dict[str, str] = {}
    for key, raw in _SET.findall(Path(path).read_text()):
        parts = shlex.split(raw) if raw else [""]
        fields[key] = parts[0] if len(parts) == 1 else " ".join(parts)
    if "NAME" not in fields:
        return None
    missing = [k for k in REQUIRED if k not in fields]
    if missing:
        raise TargetError(f"{path}: target {fields['NAME']!r} lacks SLIPEST_TARGET_{', SLIPEST_TARGET_'.join(missing)}")
    if fields["ENDIAN"] not in ("little", "big") or fields["QEMU_MODE"] not in ("system", "user"):
        raise TargetError(f"{path}: SLIPEST_TARGET_ENDIAN must be little|big and QEMU_MODE system|user")
    return Target(name=fields["NAME"], description=fields["DESCRIPTION"], file=Path(path).resolve(),
                  compiler=fields["COMPILER"], reference=_on(fields.get("REFERENCE", "OFF")), endian=fields["ENDIAN"], fpu=_on(fields["FPU"]), integer_only=_on(fields["INTEGER_ONLY"]),
                  qemu=fields["QEMU"], qemu_mode=fields["QEMU_MODE"], qemu_machine=fields.get("QEMU_MACHINE", "none"),
                  qemu_cpu=fields.get("QEMU_CPU", ""), report=fields["REPORT"], vectors=fields["VECTORS"],
                  counter=fields["COUNTER"], unaligned_trap=_on(fields.get("UNALIGNED_TRAP", "OFF")), cpu_flags=tuple(shlex.split(m.group(1)) if (m := _CPU_FLAGS.search(
                      Path(path).read_text())) else ()))


def target_dirs() -> list[Path]:
    extra = [Path(p) for p in os.environ.get(ENV_DIRS, "").split(os.pathsep) if p.strip()]
    return [repo_root() / "firmware_c" / "cmake", *extra]


def discover() -> dict[str, Target]:
    """Every target file in the target directories, by name (sorted); a name defined twice is an error."""
    found: dict[str, Target] = {}
    for d in target_dirs():
        if not d.is_dir():
            raise TargetError(f"{d}: not a directory (from {ENV_DIRS}?)")
        for path in sorted(d.glob("*.cmake")):
            t = parse_target_file(path)
            if t is None:
                continue
            if t.name in found:
                raise TargetError(f"target {t.name!r} defined twice: {found[t.name].file} and {path}")
            found[t.name] = t
    return dict(sorted(found.items()))


def get(name: str) -> Target:
    targets = discover()
    if name not in targets:
        raise TargetError(f"unknown CPU target {name!r}; known: {', '.join(targets)}")
    return targets[name]


def reference() -> Target:
    """The one target marked SLIPEST_TARGET_REFERENCE (its figures are quoted first everywhere)."""
    refs = [t for t in discover().values() if t.reference]
    if len(refs) != 1:
        raise TargetError(f"exactly one target file must set SLIPEST_TARGET_REFERENCE ON, found {len(refs)}")
    return refs[0]
