"""scripts/fuzz_stats.py: the long-mode record merges per target, so fuzz-stats.json keeps every target's
last campaign across batches (what `fleetlab assure` reports), and a crash anywhere marks the file unclean."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "scripts" / "fuzz_stats.py"


def run(*args: str) -> str:
    return subprocess.run([sys.executable, str(SCRIPT), *args], check=True, capture_output=True, text=True).stdout


def log(tmp_path: Path, name: str, executions: int | None) -> Path:
    """The tail of a libFuzzer log as -print_final_stats=1 writes it (none: the run died first)."""
    p = tmp_path / f"{name}.log"
    body = "#1024\tpulse  cov: 10 ft: 12 corp: 3/9b\n"
    if executions is not None:
        body += f"Done {executions} runs in 5 second(s)\nstat::number_of_executed_units: {executions}\n" \
                "stat::average_exec_per_sec:     2\n"
    p.write_text(body)
    return p


def test_long_mode_merges_targets_across_batches(tmp_path):
    stats = tmp_path / "b" / "fuzz-stats.json"
    run("record", str(stats), "fuzz_cobs", str(log(tmp_path, "cobs", 10_000_000)), "119", "true")
    run("record", str(stats), "fuzz_slcan", str(log(tmp_path, "slcan", 10_000_000)), "310", "true")
    run("add", str(stats), "fuzz_push", "--executions", "10000000", "--seconds", "1257", "--date", "2026-11-23",
        "--source", "lead's notes")
    # a second batch of one target replaces that target only
    run("record", str(stats), "fuzz_cobs", str(log(tmp_path, "cobs2", 12_000_000)), "150", "true")
    st = json.loads(stats.read_text())
    assert set(st["targets"]) == {"fuzz_cobs", "fuzz_slcan", "fuzz_push"}
    assert st["targets"]["fuzz_cobs"]["executions"] == 12_000_000 and st["targets"]["fuzz_cobs"]["seconds"] == 150
    assert st["targets"]["fuzz_cobs"]["exec_per_s"] == 80_000
    assert st["targets"]["fuzz_slcan"]["executions"] == 10_000_000
    assert st["targets"]["fuzz_push"]["source"] == "lead's notes" and st["targets"]["fuzz_push"]["date"] == "2026-11-23"
    assert st["mode"] == "long" and st["clean"] is True
    table = run("table", str(stats))
    assert "| fuzz_push | 10,000,000 | 1,257 | 7,955 | 2026-11-23 | yes | lead's notes |" in table


def test_a_crash_is_kept_and_marks_the_file_unclean(tmp_path):
    stats = tmp_path / "fuzz-stats.json"
    run("record", str(stats), "fuzz_cobs", str(log(tmp_path, "cobs", 10_000_000)), "119", "true")
    run("record", str(stats), "fuzz_store", str(log(tmp_path, "store", None)), "3", "false")
    st = json.loads(stats.read_text())
    assert st["targets"]["fuzz_store"] == {**st["targets"]["fuzz_store"], "executions": 0, "clean": False}
    assert st["clean"] is False
    # --fresh (or short mode's new file) forgets earlier targets
    run("record", str(stats), "fuzz_cobs", str(log(tmp_path, "cobs", 5)), "1", "true", "--fresh", "--mode", "short")
    st = json.loads(stats.read_text())
    assert list(st["targets"]) == ["fuzz_cobs"] and st["mode"] == "short" and st["clean"] is True


def test_a_file_of_the_old_format_is_merged_into(tmp_path):
    """fuzz.sh wrote one date and one clean flag for all targets before: they carry over to each target."""
    stats = tmp_path / "fuzz-stats.json"
    stats.write_text(json.dumps({"mode": "long", "date": "2026-11-23T10:00:00Z", "sanitizers": "address,undefined",
                                 "targets": {"fuzz_image": {"executions": 10914310, "seconds": 343}}, "clean": True}))
    run("record", str(stats), "fuzz_cobs", str(log(tmp_path, "cobs", 10_000_000)), "119", "true")
    st = json.loads(stats.read_text())
    old = st["targets"]["fuzz_image"]
    assert old["executions"] == 10914310 and old["clean"] is True and old["date"] == "2026-11-23"
    assert old["exec_per_s"] == 31820 and "before per-target records" in old["source"]
    assert st["clean"] is True and set(st["targets"]) == {"fuzz_image", "fuzz_cobs"}
