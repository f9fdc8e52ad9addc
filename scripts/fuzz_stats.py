#!/usr/bin/env python3
"""Keeps fuzz-stats.json, the per-target record of the last fuzz campaign that `fleetlab assure` reports.

scripts/fuzz.sh calls `record` after each target. In long mode it merges: a campaign of some targets
replaces only those targets' entries, so the file keeps every target's last campaign, not only the last
batch. `add` enters a campaign that was run elsewhere (e.g. figures from an engineer's notes), with
--source saying where the figures come from.

  fuzz_stats.py record STATS TARGET LOG SECONDS CLEAN [--fresh] [--mode long|short]
  fuzz_stats.py add STATS TARGET --executions N --seconds S --date YYYY-MM-DD --source TEXT [--crash]
  fuzz_stats.py table STATS        markdown table of the targets (docs/assurance.md keeps one)

Only the standard library: fuzz.sh runs it with whatever python3 is on the PATH.
"""
from __future__ import annotations

import argparse
import datetime as dt
import json
import re
import sys
from pathlib import Path

SANITIZERS = "address,undefined"


def executions_from_log(log: Path) -> int:
    """libFuzzer's own count (-print_final_stats=1); 0 when the run died before printing it."""
    found = re.findall(r"^stat::number_of_executed_units:\s*(\d+)", log.read_text(errors="replace"), flags=re.M)
    return int(found[-1]) if found else 0


def load(stats: Path, fresh: bool) -> dict:
    if stats.exists() and not fresh:
        data = json.loads(stats.read_text())
        data.setdefault("targets", {})
        for t in data["targets"].values():
            # a file of the fuzz.sh before per-target records: its one date and clean flag held for all
            t.setdefault("clean", bool(data.get("clean", False)))
            t.setdefault("date", str(data.get("date", "-"))[:10])
            t.setdefault("source", f"scripts/fuzz.sh, {data.get('mode', '?')} mode (file of before per-target records)")
            t.setdefault("exec_per_s", round(t["executions"] / t["seconds"]) if t.get("seconds") else None)
        return data
    return {"targets": {}}


def entry(executions: int, seconds: int, clean: bool, date: str, source: str) -> dict:
    return {"executions": executions, "seconds": seconds,
            "exec_per_s": round(executions / seconds) if seconds > 0 else None,
            "date": date, "clean": clean, "source": source}


def save(stats: Path, data: dict, mode: str) -> None:
    targets = data["targets"]
    data.update({
        # a merged file holds campaigns of several dates: "date" is the last update, each target has its own
        "mode": mode,
        "date": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "sanitizers": SANITIZERS,
        "clean": all(t["clean"] for t in targets.values()),
    })
    data["targets"] = dict(sorted(targets.items()))
    stats.parent.mkdir(parents=True, exist_ok=True)
    tmp = stats.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n")
    tmp.replace(stats)  # a campaign killed mid-write leaves the previous file, not half of one


def table(data: dict) -> str:
    rows = ["| Target | Executions | Seconds | exec/s | Date | Clean | Source |", "|---|---:|---:|---:|---|---|---|"]
    for name, t in data["targets"].items():
        rate = f"{t['exec_per_s']:,}" if t.get("exec_per_s") else "-"
        rows.append(f"| {name} | {t['executions']:,} | {t['seconds']:,} | {rate} | {t.get('date', '-')} | "
                    f"{'yes' if t['clean'] else 'NO'} | {t.get('source', '-')} |")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("record", help="record one target's run from its libFuzzer log")
    r.add_argument("stats", type=Path)
    r.add_argument("target")
    r.add_argument("log", type=Path)
    r.add_argument("seconds", type=int)
    r.add_argument("clean", choices=["true", "false"])
    r.add_argument("--fresh", action="store_true", help="start a new file instead of merging")
    r.add_argument("--mode", default="long", choices=["long", "short"])
    a = sub.add_parser("add", help="enter a campaign run elsewhere")
    a.add_argument("stats", type=Path)
    a.add_argument("target")
    a.add_argument("--executions", type=int, required=True)
    a.add_argument("--seconds", type=int, required=True)
    a.add_argument("--date", required=True)
    a.add_argument("--source", required=True)
    a.add_argument("--crash", action="store_true", help="the campaign did not end clean")
    t = sub.add_parser("table", help="print the targets as a markdown table")
    t.add_argument("stats", type=Path)
    args = p.parse_args(argv)

    if args.cmd == "table":
        print(table(load(args.stats, fresh=False)))
        return 0
    if args.cmd == "record":
        data = load(args.stats, args.fresh)
        today = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d")
        data["targets"][args.target] = entry(executions_from_log(args.log), args.seconds, args.clean == "true",
                                             today, f"scripts/fuzz.sh, {args.mode} mode ({args.log.parent.parent.name})")
        save(args.stats, data, args.mode)
        return 0
    if not re.fullmatch(r"\d{4}-\d{2}-\d{2}", args.date):
        p.error("--date must be YYYY-MM-DD")
    data = load(args.stats, fresh=False)
    data["targets"][args.target] = entry(args.executions, args.seconds, not args.crash, args.date, args.source)
    save(args.stats, data, "long")
    return 0


if __name__ == "__main__":
    sys.exit(main())
