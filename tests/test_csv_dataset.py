import json

import numpy as np
import pytest

from fleetlab.data.contracts import CSV_COLUMNS
from fleetlab.data.csvio import CsvFormatError, WindowTable, read_windows_csv, write_windows_csv
from fleetlab.data.dataset import load_dataset, role_of_fleet_to_lab_file, write_manifest

HEADER = ",".join(CSV_COLUMNS)
ROW = "1,0.1,50,2,0.1,0.3,0.0,0.2,9.8,0.3,-0.1,0.05,0.9,1.0,10.0,0,100,2.0"


def _write(path, lines, eol="\r\n"):
    path.write_bytes(eol.join(lines).encode() + eol.encode())
    return path


@pytest.mark.parametrize("eol", ["\r\n", "\n"])
def test_reads_crlf_and_lf(tmp_path, eol):
    t = read_windows_csv(_write(tmp_path / "a.csv", [HEADER, ROW, ROW], eol))
    assert len(t) == 2 and t.features.shape == (2, 12)
    assert t.label.tolist() == [0, 0] and t.d_commanded.tolist() == [1.0, 1.0]


def test_wrong_field_count_names_file_and_line(tmp_path):
    p = _write(tmp_path / "bad.csv", [HEADER, ROW, ROW + ",7"])
    with pytest.raises(CsvFormatError, match=r"bad\.csv:3: expected 18 fields, found 19"):
        read_windows_csv(p)


def test_non_number_names_column(tmp_path):
    p = _write(tmp_path / "bad.csv", [HEADER, ROW.replace("50", "fifty", 1)])
    with pytest.raises(CsvFormatError, match=r"bad\.csv:2: column feat_curr_mean: 'fifty'"):
        read_windows_csv(p)


def test_bad_header_and_bad_class(tmp_path):
    with pytest.raises(CsvFormatError, match=r":1: header .*missing \['feat_roll_mean'\]"):
        read_windows_csv(_write(tmp_path / "h.csv", [HEADER.replace("feat_roll_mean", "roll")]))
    with pytest.raises(CsvFormatError, match="slip_class: 3"):
        read_windows_csv(_write(tmp_path / "c.csv", [HEADER, ROW.replace(",0,100,", ",3,100,")]))
    with pytest.raises(CsvFormatError, match="empty file"):
        read_windows_csv(_write(tmp_path / "e.csv", [], ""))


def test_nonfinite_rows_rejected_and_counted(tmp_path):
    lines = [HEADER, ROW, ROW.replace("50", "nan", 1), ROW.replace("0.9", "inf", 1), ROW]
    t = read_windows_csv(_write(tmp_path / "n.csv", lines))
    assert len(t) == 2
    assert t.rejected_nonfinite == 2 and t.rejected_lines == [3, 4]
    assert np.isfinite(t.features).all()


def test_write_read_roundtrip_is_exact(tmp_path):
    rng = np.random.default_rng(0)
    n = 17
    t = WindowTable(
        features=rng.normal(size=(n, 12)), d_actual=rng.random(n), d_commanded=rng.random(n) + 0.1,
        slip_pct=rng.normal(size=n) * 30, label=rng.integers(0, 3, n), n_samples=np.full(n, 100),
        duration_s=np.full(n, 2.0),
    )
    write_windows_csv(tmp_path / "r.csv", t)
    assert (tmp_path / "r.csv").read_bytes().count(b"\r\n") == n + 1
    back = read_windows_csv(tmp_path / "r.csv")
    for name in ("features", "d_actual", "d_commanded", "slip_pct", "label", "n_samples", "duration_s"):
        np.testing.assert_array_equal(getattr(back, name), getattr(t, name))


def test_fleet_to_lab_names_map_to_roles():
    f = "training_data_{}_default_friction_particle_0_01_density_0_0125_size_part3.csv"
    assert role_of_fleet_to_lab_file(f.format("leo_rover_lunalab")) == "earth"
    assert role_of_fleet_to_lab_file(f.format("leo_rover_default_moon")) == "target"
    assert role_of_fleet_to_lab_file(f.format("cadre_default_moon")) == "fleet_cadre"
    assert role_of_fleet_to_lab_file(f.format("husky_default_moon")) == "fleet_husky"
    assert role_of_fleet_to_lab_file("notes.csv") is None


def test_real_fleet_to_lab_folder(real_data_dir):
    ds = load_dataset(real_data_dir)
    assert ds.source == "fleet-to-lab names"
    rows = {r: len(ds.table(r)) for r in ds.roles}
    assert rows == {"earth": 2195, "fleet_cadre": 1947, "fleet_husky": 1848, "target": 1367}
    assert ds.table("target").class_counts() == [888, 271, 208]
    assert ds.rejected_nonfinite == 0
    ds.check_roles()
    assert len(np.unique(ds.groups("target"))) == 5


def test_manifest_folder_and_errors(tmp_path):
    _write(tmp_path / "e.csv", [HEADER, ROW])
    _write(tmp_path / "t.csv", [HEADER, ROW, ROW])
    write_manifest(tmp_path, {"e.csv": {"role": "earth"}, "t.csv": {"role": "target"}}, {"seed": 1})
    ds = load_dataset(tmp_path)
    assert ds.source == "manifest" and ds.roles == ["earth", "target"]
    with pytest.raises(ValueError, match="no fleet_<rover>"):
        ds.check_roles()
    meta = json.loads((tmp_path / "dataset.json").read_text())
    meta["files"]["gone.csv"] = {"role": "target"}
    (tmp_path / "dataset.json").write_text(json.dumps(meta))
    with pytest.raises(CsvFormatError, match="gone.csv: listed in dataset.json but missing"):
        load_dataset(tmp_path)
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="no dataset.json and no files named like"):
        load_dataset(empty)
