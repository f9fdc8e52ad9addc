"""The user guides quote real, tested code: the example files appear in the guide verbatim."""

from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
QUOTED = ("example_board.h", "minimal_can_loop.c", "minimal_sample_loop.c")


def test_integration_guide_quotes_the_example_files_in_full():
    guide = (REPO / "docs" / "integrating_slipest.md").read_text()
    for name in QUOTED:
        code = (REPO / "firmware_c" / "examples" / name).read_text().rstrip("\n")
        assert f"```c\n{code}\n```" in guide, f"docs/integrating_slipest.md does not quote {name} as it is"


def test_readme_links_both_guides():
    readme = (REPO / "README.md").read_text()
    assert "docs/integrating_slipest.md" in readme and "docs/can_interface.md" in readme


def _documented_commands() -> list[tuple[str, str]]:
    """(file, command) for every `fleetlab ...` line inside a bash/sh block of the README and the guides;
    synopsis lines ("[--opt X]", "a|b") are usage patterns, not commands, and are left out."""
    import re

    found = []
    for path in [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]:
        for block in re.findall(r"```(?:bash|sh)\n(.*?)```", path.read_text(), flags=re.S):
            for line in block.replace("\\\n", " ").splitlines():
                line = line.split(" #")[0].strip()
                if line.startswith("fleetlab ") and not re.search(r"\[|\w\|\w", line):
                    found.append((path.name, line))
    return found


def test_documented_commands_parse():
    """Every fleetlab command the guides show names a real subcommand and real options."""
    import shlex

    from fleetlab.cli import build_parser

    commands = _documented_commands()
    assert len(commands) > 20 and any("--fleet-ablation" in c for _, c in commands)
    for name, line in commands:
        argv = shlex.split(line)[1:]
        try:
            args = build_parser(argv[0]).parse_args(argv)
        except SystemExit:
            raise AssertionError(f"{name}: '{line}' does not parse") from None
        assert getattr(args, "_module", None), f"{name}: '{line}' names no subcommand"


def test_architecture_doc_maps_every_package_folder():
    """docs/architecture.md and the README's Layout name every folder that pyproject maps into `fleetlab`."""
    import tomllib

    mapping = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    arch = (REPO / "docs" / "architecture.md").read_text()
    readme = (REPO / "README.md").read_text()
    assert "docs/architecture.md" in readme
    for name, folder in mapping.items():
        assert f"| `{folder}/` | `{name}` |" in arch, f"docs/architecture.md: no layout row for {folder}/ ({name})"
        assert f"`{folder}/`" in readme, f"README Layout does not name {folder}/"
