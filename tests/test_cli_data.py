import json
import subprocess
import sys


def _fleetlab(*args):
    return subprocess.run([sys.executable, "-m", "fleetlab.cli", *args], capture_output=True, text=True)


def test_help_lists_subcommands():
    r = _fleetlab("--help")
    assert r.returncode == 0
    for cmd in ("simulate", "data", "fuse", "evaluate", "export", "emulate", "stream", "bench", "demo"):
        assert cmd in r.stdout, cmd


def test_data_info_json_on_real_files(real_data_dir):
    r = _fleetlab("data", "info", str(real_data_dir), "--json")
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    assert info["total_rows"] == 7357
    assert info["roles"]["target"] == {"rows": 1367, "classes": [888, 271, 208], "files": 5}
    assert info["roles"]["earth"]["classes"] == [1908, 236, 51]
    assert set(info["roles"]) == {"earth", "fleet_cadre", "fleet_husky", "target"}


def test_data_info_plot_and_bad_path(real_data_dir, tmp_path):
    r = _fleetlab("data", "info", str(real_data_dir), "--plot", str(tmp_path / "h.png"))
    assert r.returncode == 0 and (tmp_path / "h.png").stat().st_size > 10_000
    assert "fleet_husky" in r.stdout
    r = _fleetlab("data", "info", str(tmp_path / "missing"))
    assert r.returncode == 1 and "not a directory" in r.stderr and "Traceback" not in r.stderr


def test_malformed_csv_gives_one_line_error(tmp_path):
    (tmp_path / "training_data_leo_rover_lunalab_x_part1.csv").write_text("a,b\n1,2\n")
    r = _fleetlab("data", "info", str(tmp_path))
    assert r.returncode == 1 and "part1.csv:1: header" in r.stderr and "Traceback" not in r.stderr
