"""Build the C estimator (CMake) and run the host emulator `slipest_emu` on a pseudo-terminal.

`fleetlab emulate` builds on demand: one build directory per bundle and DBC under
`<build root>/emulate*` (`fleetlab.paths.build_root`: `build/` in a clone, the user's cache folder for
an installed wheel, `$FLEETLAB_BUILD_ROOT` if set), configured with
`-DSLIPEST_BUNDLE=<bundle> -DSLIPEST_DBC=<dbc in use>`, guarded by a file lock so concurrent
runs do not race. The emulator opens a pty itself and prints its path; we read it from
the emulator's stdout.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import re
import signal
import subprocess
import threading
import time
from pathlib import Path

from fleetlab.export import image_layout
from fleetlab.paths import build_root, default_bundle
from fleetlab.system_tools import need
from .wire.dbc import DBC_PATH, dbc_path
from .firmware.build import build_command, configure_command
from fleetlab.errors import FleetlabError, InputError

EMULATOR_TARGET = "slipest_emu"
HOST_LIBRARY_TARGET = "slipest_host"
PTY_RE = re.compile(rb"(/dev/pts/\d+|/dev/tty\w+)")


def _is_table_image(data: bytes) -> bool:
    """Whether a model image is format 2 (a layer table): its format field sits at the same offset in every format."""
    at = image_layout.V1.offsets["format"]
    return len(data) >= at + 2 and int.from_bytes(data[at:at + 2], "little") == image_layout.V2.version


def build_dir_for(bundle: Path, dbc: Path | None = None, options: dict[str, str] | None = None) -> Path:
    bundle, dbc = bundle.resolve(), (dbc or dbc_path()).resolve()
    default_dbc = dbc == DBC_PATH.resolve()
    # our own build dirs (not build/host, which people configure by hand, e.g. with sanitizers
    # that a ctypes load cannot take)
    if bundle == default_bundle().resolve() and default_dbc and not options:
        return build_root() / "emulate"
    key = str(bundle) if default_dbc else f"{bundle}|{dbc}"
    key += "".join(f"|{k}={v}" for k, v in sorted((options or {}).items()))
    tag = hashlib.sha256(key.encode()).hexdigest()[:10]
    return build_root() / f"emulate-{tag}"


def _bundle_stamp(bundle: Path, dbc: Path) -> str:
    """Content hash of the bundle's headers and of the DBC: a change forces a reconfigure."""
    h = hashlib.sha256()
    for name in sorted(p.name for p in bundle.glob("*.h")):
        h.update(name.encode() + (bundle / name).read_bytes())
    h.update(str(dbc).encode() + dbc.read_bytes())
    return h.hexdigest()


_BUILT: set[tuple[Path, tuple[str, ...], str]] = set()  # up to date in this process


def build(bundle: Path | str | None = None, targets: tuple[str, ...] = (EMULATOR_TARGET, HOST_LIBRARY_TARGET),
          quiet: bool = True, options: dict[str, str] | None = None) -> Path:
    """Configure (if needed) and build the host targets for `bundle` and the DBC in use
    (`dbc.dbc_path()`); returns the build dir.

    CMake's own up-to-date check takes about a second, so a process asks it once per
    bundle and target set. `options`: more CMake cache settings (their own build dir), e.g.
    SLIPEST_LAYER_TABLE=ON for a node that takes format-2 images of any architecture.
    """
    bundle = Path(bundle) if bundle else default_bundle()
    if not (bundle / "slipest_model_q.h").is_file():
        raise OSError(f"{bundle}: not an export bundle (no slipest_model_q.h)")
    need("cmake", "building the host emulator (fleetlab emulate, stream, upload --emulate)")
    dbc = dbc_path()
    bdir = build_dir_for(bundle, dbc, options)
    bdir.mkdir(parents=True, exist_ok=True)
    stamp = _bundle_stamp(bundle, dbc) + "".join(f"|{k}={v}" for k, v in sorted((options or {}).items()))
    key = (bdir, tuple(targets), stamp)
    if key in _BUILT:
        return bdir
    out = subprocess.DEVNULL if quiet else None
    with open(bdir / ".fleetlab.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        stamp_file = bdir / ".fleetlab-bundle-stamp"
        if not (bdir / "CMakeCache.txt").is_file() or not stamp_file.is_file() or stamp_file.read_text() != stamp:
            cmd = configure_command(bdir, bundle, options={"SLIPEST_DBC": str(dbc), "SLIPEST_SANITIZE": "OFF",
                                                           "SLIPEST_FUZZ": "OFF", **(options or {})})
            r = subprocess.run(cmd, stdout=out, stderr=subprocess.PIPE, text=True)
            if r.returncode:
                raise OSError(f"cmake configure failed for bundle {bundle}:\n{r.stderr[-2000:]}")
        r = subprocess.run(build_command(bdir, os.cpu_count() or 2, tuple(targets)),
                           stdout=out, stderr=subprocess.PIPE, text=True)
        if r.returncode:
            raise OSError(f"cmake build failed ({', '.join(targets)}):\n{r.stderr[-2000:]}")
        stamp_file.write_text(stamp)
    _BUILT.add(key)
    return bdir


def find_artifact(bdir: Path, name: str) -> Path:
    hits = sorted(p for p in bdir.rglob(name) if p.is_file())
    if not hits:
        raise OSError(f"{bdir}: built, but no {name} found")
    return hits[0]


def host_library(bundle: Path | str | None = None) -> Path:
    """Path of the ctypes library (libslipest_host.so) for `bundle`, built if needed."""
    bdir = build(bundle)
    return find_artifact(bdir, "libslipest_host.so")


class EmulatorProcess:
    """The `slipest_emu` process on a pty (`--link slcan` or `--link cobs`)."""

    def __init__(self, exe: Path, link: str, start_timeout: float = 10.0, model: Path | None = None):
        if link not in ("slcan", "cobs"):
            raise InputError(f"emulator link must be 'slcan' or 'cobs', got {link!r}")
        self.exe, self.link, self.start_timeout = Path(exe), link, start_timeout
        self.model = Path(model) if model is not None else None  # model.img served instead of the built-in one
        self.proc: subprocess.Popen | None = None
        self.pty_path: str | None = None
        self.starts = 0
        self._stderr_tail: list[str] = []

    @classmethod
    def for_bundle(cls, bundle: Path | str | None, link: str) -> "EmulatorProcess":
        img = Path(bundle or default_bundle()) / "model.img"
        if img.is_file() and not _is_table_image(img.read_bytes()):
            # one emulator build serves every SN-S bundle: it reads the bundle's model image at run time
            return cls(find_artifact(build(None), EMULATOR_TARGET), link, model=img)
        # a layer-table bundle (format-2 image: the default build has no layer-table kernels) or one without
        # model.img (exported before it existed): built in
        bdir = build(bundle)
        return cls(find_artifact(bdir, EMULATOR_TARGET), link)

    def start(self) -> str:
        """Start the emulator; returns the pty path it serves."""
        if self.proc is not None:
            # a second start would leave the first process running with nobody to stop it
            raise FleetlabError(f"{self.exe.name} is running already (pid {self.proc.pid}): stop it before starting it again")
        model = ["--model", str(self.model)] if self.model is not None else []
        self.proc = subprocess.Popen([str(self.exe), *model, "--pty", "--link", self.link], stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, start_new_session=True)
        self.starts += 1
        line_buf = b""
        deadline = time.monotonic() + self.start_timeout
        assert self.proc.stdout is not None
        while time.monotonic() < deadline:
            line = self.proc.stdout.readline()
            if not line:
                break
            line_buf += line
            m = PTY_RE.search(line)
            if m:
                self.pty_path = m.group(1).decode()
                break
        if self.pty_path is None:
            err = self._drain_stderr()
            self.stop()
            raise OSError(f"{self.exe.name} did not report its pty: {line_buf[-200:]!r} {err}")
        # keep stdout/stderr from filling up and blocking the emulator
        for stream, keep in ((self.proc.stdout, False), (self.proc.stderr, True)):
            threading.Thread(target=self._pump, args=(stream, keep), daemon=True).start()
        return self.pty_path

    def _pump(self, stream, keep: bool) -> None:
        for line in iter(stream.readline, b""):
            if keep:
                self._stderr_tail = (self._stderr_tail + [line.decode(errors="replace").rstrip()])[-20:]

    def _drain_stderr(self) -> str:
        if self.proc is None or self.proc.stderr is None:
            return ""
        try:
            self.proc.wait(timeout=0.2)
            return self.proc.stderr.read().decode(errors="replace")[-1000:]
        except subprocess.TimeoutExpired:
            return ""

    @property
    def running(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def kill(self) -> None:
        """Hard kill (fault injection: the estimator dies mid-stream)."""
        if self.proc is not None:
            if self.proc.poll() is None:
                self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(timeout=5)
            self.proc = None
            self.pty_path = None

    def stop(self) -> int | None:
        """Polite stop (SIGTERM, then SIGKILL); returns the exit code."""
        if self.proc is None:
            return None
        p = self.proc
        if p.poll() is None:
            p.terminate()
            try:
                p.wait(timeout=3)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout=3)
        self.proc, self.pty_path = None, None
        return p.returncode

    def restart(self) -> str:
        self.kill()
        return self.start()

    def stderr_tail(self) -> str:
        return "\n".join(self._stderr_tail)

    def __enter__(self) -> "EmulatorProcess":
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()
