"""One option set: every long-running command takes --no-progress (issue 43 item 8, issue 44)."""

from __future__ import annotations

import pytest

from fleetlab.cli import build_parser

LONG_RUNNING = [["fuse"], ["evaluate"], ["export"], ["emulate"], ["upload"], ["stream", "can"], ["stream", "serial"]]


@pytest.mark.parametrize("command", LONG_RUNNING, ids=" ".join)
def test_long_running_commands_take_no_progress(command, capsys):
    parser = build_parser(command[0])
    with pytest.raises(SystemExit) as e:
        parser.parse_args([*command, "--help"])
    assert e.value.code == 0
    assert "--no-progress" in capsys.readouterr().out
