"""No traceback for a user's mistake or a missing tool (issue 26): one line naming what is missing, the
command that needs it and how to install it, exit status 2; importing fleetlab touches no file."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from fleetlab import system_tools
from fleetlab.host_tools.firmware import targets
from fleetlab.paths import repo_root

REPO = repo_root()


def _apt_packages() -> set[str]:
    lines = (REPO / "scripts" / "apt-packages.txt").read_text().splitlines()
    return {line.split()[0] for line in lines if line.strip() and not line.lstrip().startswith("#")}


def _path_without(tool: str, tmp: Path) -> str:
    """PATH with `tool` hidden: each folder holding it is replaced by a folder of links to everything else."""
    dirs = []
    for i, d in enumerate(os.environ["PATH"].split(os.pathsep)):
        if d and (Path(d) / tool).exists():
            shadow = tmp / f"path{i}"
            shadow.mkdir()
            for entry in Path(d).iterdir():
                if entry.name != tool:
                    (shadow / entry.name).symlink_to(entry)
            d = str(shadow)
        dirs.append(d)
    return os.pathsep.join(dirs)


def _fleetlab(args: list[str], cwd: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "fleetlab.cli", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=300)


def test_assure_without_cppcheck_is_one_line_and_exit_2(tmp_path):
    env = {**os.environ, "PATH": _path_without("cppcheck", tmp_path)}
    res = _fleetlab(["assure", "--out", str(tmp_path / "out")], tmp_path, env)
    assert res.returncode == 2, res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert "cppcheck not found" in lines[0] and "fleetlab assure" in lines[0]
    assert "bash scripts/setup.sh" in lines[0] and "apt-get install cppcheck" in lines[0]


def test_a_missing_cross_compiler_names_the_target_and_its_package(tmp_path):
    res = _fleetlab(["bench", "c", "--target", "cortex-m4", "--build-dir", str(tmp_path / "b")], tmp_path,
                    {**os.environ, "PATH": _path_without("arm-none-eabi-gcc", tmp_path)})
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert "arm-none-eabi-gcc not found" in res.stderr and "--target cortex-m4" in res.stderr
    assert "apt-get install gcc-arm-none-eabi" in res.stderr


# the host tools fleetlab runs itself (builds, assure's analysers, stack and float checks)
HOST_TOOLS = {"cmake", "ctest", "gcc", "gcov", "clang", "doxygen", "cppcheck", "clang-tidy", "frama-c",
              "arm-none-eabi-gcc", "arm-none-eabi-nm"}


def test_every_tool_has_a_package_that_setup_installs():
    """A missing tool's error names its Debian package from scripts/apt-packages.txt: every tool fleetlab runs,
    every CPU target's compiler and emulator included, must be listed there under a package setup installs."""
    tools = set(HOST_TOOLS)
    for t in targets.discover().values():
        tools |= set(t.tools)
    listed = system_tools.packages()
    assert tools <= listed.keys(), sorted(tools - listed.keys())
    assert set(listed.values()) <= _apt_packages()


def test_help_works_outside_any_clone(tmp_path):
    for args in (["--help"], ["bench", "c", "--help"], ["assure", "--help"], ["c-sources", "--help"]):
        res = _fleetlab(args, tmp_path)
        assert res.returncode == 0 and res.stdout.startswith("usage: fleetlab"), (args, res.stderr)


def test_importing_any_module_touches_no_source_tree_location():
    """Every module of fleetlab imports while the source tree cannot be found: no module computes a path of
    the tree (or the bundle, or the build root) when it is imported."""
    code = r"""
import importlib, pkgutil
import fleetlab, fleetlab.paths as paths

def nowhere():
    raise AssertionError("a module asked for the source tree at import time")

paths._tree = nowhere
names = [m.name for m in pkgutil.walk_packages(fleetlab.__path__, "fleetlab.") if not m.name.endswith("__main__")]
for name in names:
    importlib.import_module(name)
print(len(names))
"""
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    assert int(res.stdout.strip()) >= 60  # every module, not a few


@pytest.mark.parametrize("args, says", [
    (["export", "no-such-model.pt", "--out", "b"], "no-such-model.pt"),
    (["export", "x", "--out", "b"], "x: cannot read model file (empty or cut short)"),
    (["emulate", "--bundle", "no-such-bundle"], "no-such-bundle"),
    (["bench", "c", "--target", "no-such-cpu"], "no-such-cpu"),
    (["c-sources", "--out", "."], "not an empty folder"),
])
def test_user_mistakes_are_one_line(tmp_path, args, says):
    (tmp_path / "x").write_text("")  # so that "." is not empty
    res = _fleetlab(args, tmp_path)
    assert res.returncode in (1, 2) and "Traceback" not in res.stderr, res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and says in res.stderr, res.stderr


def test_options_are_taken_by_their_full_names_only(capsys):
    """`--model` is not an option of export: it is refused as such, not taken for `--model-version`."""
    from fleetlab.cli import main

    for args, unknown in ((["export", "--model", "m.pt"], "--model"),
                          (["evaluate", "--data", "d", "--run", "3"], "--run")):  # a prefix of --runs and --rng
        with pytest.raises(SystemExit) as stopped:
            main(args)
        err = capsys.readouterr().err
        assert stopped.value.code == 2 and f"unrecognized arguments: {unknown}" in err, err
        assert "invalid int" not in err, err


def test_a_reader_that_stops_early_is_no_error(tmp_path):
    """`fleetlab data info DIR | head`: the reader closes the pipe before the output is written. The command
    stops quietly with 141 (128 + SIGPIPE, as a shell tool would), without Python's broken-pipe message."""
    sim = tmp_path / "sim"
    made = _fleetlab(["simulate", "--out", str(sim), "--scale", "0.05"], tmp_path)
    assert made.returncode == 0, made.stderr
    proc = subprocess.Popen([sys.executable, "-m", "fleetlab.cli", "data", "info", str(sim)], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc.stdout.close()  # the reader is gone before the first line
    err = proc.stderr.read()
    assert proc.wait(timeout=120) == 141 and err == "", err


def test_a_broken_pipe_elsewhere_is_still_an_error(monkeypatch, capsys):
    """A pipe other than stdout (an emulator process that died, say) breaking is still said, in one line."""
    from fleetlab import cli
    from fleetlab.cli import data

    def broken(args):
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(data, "run", broken)
    assert cli.main(["data", "info", "x"]) == 1
    assert capsys.readouterr().err == "fleetlab data: error: [Errno 32] Broken pipe\n"


def _raising(error: BaseException):
    def run(args):
        raise error
    return run


def test_an_unexpected_error_is_an_internal_error_not_bad_input(monkeypatch, capsys):
    """A ValueError fleetlab did not raise on purpose (numpy's, a bug's) is not the user's mistake: one line that
    says so and how to see the traceback, and its own exit status (before: "error: ..." and exit 1, as bad input)."""
    from fleetlab import cli
    from fleetlab.cli import data

    monkeypatch.setattr(data, "run", _raising(ValueError("operands could not be broadcast together")))
    assert cli.main(["data", "info", "x"]) == cli.INTERNAL_EXIT != 1
    err = capsys.readouterr().err
    assert err.splitlines() == [
        "fleetlab data: internal error (ValueError: operands could not be broadcast together); "
        "rerun with `fleetlab --debug data ...` for the traceback and report it"], err


def test_debug_shows_the_traceback(monkeypatch, tmp_path):
    """`fleetlab --debug COMMAND` lets the error end with its traceback: in this process it is raised, and run as
    a command the interpreter prints it."""
    from fleetlab import cli
    from fleetlab.cli import data

    monkeypatch.setattr(data, "run", _raising(ValueError("planted")))
    with pytest.raises(ValueError, match="planted"):
        cli.main(["--debug", "data", "info", "x"])
    monkeypatch.undo()
    res = _fleetlab(["--debug", "data", "info", str(tmp_path / "no-such-folder")], tmp_path)
    assert res.returncode == 1 and "Traceback (most recent call last)" in res.stderr, res.stderr
    assert "no-such-folder" in res.stderr.strip().splitlines()[-1]


def test_a_deliberate_input_error_is_still_one_line(capsys):
    """The errors the layers raise on purpose (InputError) keep their one line and exit 1, with --debug off."""
    from fleetlab import cli
    from fleetlab.errors import InputError

    assert issubclass(InputError, ValueError)  # every `except ValueError` of a layer still catches them
    assert cli.main(["bench", "data", "--samples", "10"]) == 1
    assert capsys.readouterr().err == "fleetlab bench: error: --samples must be >= 100 and --repeats >= 1\n"
    assert cli.main(["evaluate", "--data", "no-such-folder", "--label-noise-sweep", "nonsense"]) == 1
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and "Traceback" not in err and err.startswith("fleetlab evaluate: error: "), err


def test_no_runtime_error_is_raised_on_purpose():
    """A RuntimeError reads as a bug (an internal error, exit 70): what fleetlab refuses on purpose is a
    FleetlabError (or InputError) with its one line."""
    import ast

    from fleetlab.paths import repo_root

    raised = []
    for folder in ("toolchain", "export", "host_tools", "dbc", "canopen_od"):
        for path in (repo_root() / folder).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Raise) and node.exc is not None:
                    call = node.exc.func if isinstance(node.exc, ast.Call) else node.exc
                    if isinstance(call, ast.Name) and call.id == "RuntimeError":
                        raised.append(f"{path.relative_to(repo_root())}:{node.lineno}")
    assert not raised, raised
