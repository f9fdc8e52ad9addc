"""Dataset folders: which window files play which role.

Roles: `earth` (target rover in the Earth analog, D_Earth), `fleet_<rover>` (one
per fleet rover on the Moon), `target` (target rover on the Moon: D_Cal and test).
A folder made by `fleetlab simulate` or `fleetlab data import` carries `dataset.json`; a folder
of the original Fleet-To-Lab files is recognised by the file names alone; a roles file
(TOML, `load_roles_file`) names several folders and gives each a role, so one dataset can
mix imported logs with Fleet-To-Lab CSVs. A roles file that gives a folder a role also takes a
folder without `dataset.json`: every window CSV in it (Fleet-To-Lab layout) then has that role.

Windows without labels (`fleetlab data import` without ground truth) are listed apart
(`unlabelled_files` in dataset.json, `Dataset.unlabelled`): `data info` and `data compare` show
their feature statistics, and nothing trains or evaluates on them.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .csvio import UNLABELLED_SUFFIX, CsvFormatError, WindowTable, read_unlabelled_csv, read_windows_csv
from ..errors import InputError

MANIFEST_NAME = "dataset.json"
MANIFEST_FORMAT = "fleetlab-dataset/1"

EARTH = "earth"
TARGET = "target"
FLEET_PREFIX = "fleet_"

# Fleet-To-Lab file names: training_data_<rover>_<environment>_..._part<k>.csv
_F2L_PATTERN = re.compile(r"^training_data_(?P<rover>leo_rover|cadre|husky)_(?P<env>lunalab|default_moon)_.*\.csv$")
_F2L_TARGET_ROVER = "leo_rover"


def role_of_fleet_to_lab_file(name: str) -> str | None:
    """Role of an original Fleet-To-Lab file from its name, or None if it is not one."""
    m = _F2L_PATTERN.match(name)
    if not m:
        return None
    rover, env = m["rover"], m["env"]
    if rover == _F2L_TARGET_ROVER:
        return EARTH if env == "lunalab" else TARGET
    return FLEET_PREFIX + rover if env == "default_moon" else None


def _part_number(name: str) -> int:
    m = re.search(r"part(\d+)", name)
    return int(m.group(1)) if m else 0


@dataclass
class DataFile:
    path: Path
    role: str
    table: WindowTable


@dataclass
class UnlabelledFile:
    path: Path
    role: str
    features: np.ndarray  # (n, 12)


@dataclass
class Dataset:
    root: Path
    files: list[DataFile]
    source: str  # "manifest", "fleet-to-lab names", "roles file" or "role given by a roles file"
    unlabelled: list[UnlabelledFile] = field(default_factory=list)  # windows without labels: statistics only

    @property
    def roles(self) -> list[str]:
        order = {EARTH: 0, TARGET: 2}
        return sorted({f.role for f in self.files}, key=lambda r: (order.get(r, 1), r))

    @property
    def fleet_roles(self) -> list[str]:
        return [r for r in self.roles if r.startswith(FLEET_PREFIX)]

    def files_of(self, role: str) -> list[DataFile]:
        return [f for f in self.files if f.role == role]

    def table(self, role: str) -> WindowTable:
        files = self.files_of(role)
        if not files:
            raise KeyError(f"{self.root}: no files with role {role!r} (roles: {', '.join(self.roles)})")
        return WindowTable.concat([f.table for f in files])

    def xy(self, role: str) -> tuple[np.ndarray, np.ndarray]:
        t = self.table(role)
        return t.features.astype(np.float32), t.label

    def groups(self, role: str) -> np.ndarray:
        """File (traverse) index of every row of `table(role)`, for leakage-free splits."""
        return np.concatenate([np.full(len(f.table), i) for i, f in enumerate(self.files_of(role))])

    @property
    def rejected_nonfinite(self) -> int:
        return sum(f.table.rejected_nonfinite for f in self.files)

    def check_roles(self) -> None:
        """The roles that fusion needs: earth, target and at least one fleet rover."""
        missing = [r for r in (EARTH, TARGET) if r not in self.roles]
        if not self.fleet_roles:
            missing.append("fleet_<rover>")
        if missing:
            raise InputError(f"{self.root}: dataset has no {', '.join(missing)} files (found roles: {self.roles})")


ROLES_KEYS = ("path", "role")
ROLE_PATTERN = re.compile(rf"^({EARTH}|{TARGET}|{FLEET_PREFIX}[A-Za-z0-9_-]+)$")


def load_roles_file(path: Path) -> Dataset:
    """A dataset made of several folders (imports, Fleet-To-Lab CSVs, simulator output), from a TOML file:

        [[folder]]
        path = "imports/analog"   # relative to this file
        role = "earth"            # optional: every file of the folder takes this role
        [[folder]]
        path = "/data/fleet_to_lab"   # no role: the folder's own (dataset.json or Fleet-To-Lab names)
    """
    import tomllib

    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{path}: not valid TOML ({e})") from None
    extra = [k for k in data if k != "folder"]
    if extra or not isinstance(data.get("folder"), list) or not data["folder"]:
        raise InputError(f"{path}: a roles file holds only [[folder]] tables (path, optional role)"
                         + (f"; unknown key {extra[0]!r}" if extra else ""))
    files: list[DataFile] = []
    unlabelled: list[UnlabelledFile] = []
    for k, entry in enumerate(data["folder"], start=1):
        bad = [key for key in entry if key not in ROLES_KEYS]
        if bad or not isinstance(entry.get("path"), str):
            raise InputError(f"{path}: folder {k}: " + (f"unknown key {bad[0]!r} (keys: path, role)" if bad
                                                         else "needs path = \"FOLDER\""))
        role = entry.get("role")
        if role is not None and not (isinstance(role, str) and ROLE_PATTERN.match(role)):
            raise InputError(f"{path}: folder {k}: role {role!r} is not {EARTH}, {TARGET} or {FLEET_PREFIX}<rover>")
        folder = load_dataset(path.parent / entry["path"], roles_file=False, role=role)
        files += [DataFile(f.path, role or f.role, f.table) for f in folder.files]
        unlabelled += [UnlabelledFile(f.path, role or f.role, f.features) for f in folder.unlabelled]
    return Dataset(root=path, files=files, source="roles file", unlabelled=unlabelled)


def load_dataset(root: Path | str, roles_file: bool = True, role: str | None = None) -> Dataset:
    """Load every window file of a dataset folder (or of the folders a roles .toml file names) with its role.

    `role` (a roles file's): a folder without dataset.json nor Fleet-To-Lab names is then every window CSV
    in it (and every *.unlabelled.csv), all with that role."""
    root = Path(root)
    if roles_file and root.is_file() and root.suffix == ".toml":
        return load_roles_file(root)
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: not a directory" + ("" if root.exists() else " (nor a roles .toml file)"))
    manifest = root / MANIFEST_NAME
    if manifest.exists():
        try:
            meta = json.loads(manifest.read_text())
        except json.JSONDecodeError as e:
            raise InputError(f"{manifest}: not valid JSON ({e})") from None
        if meta.get("format") != MANIFEST_FORMAT:
            raise InputError(f"{manifest}: unknown format {meta.get('format')!r}, expected {MANIFEST_FORMAT!r}")
        entries = [(root / name, info["role"]) for name, info in meta["files"].items()]
        loose = [(root / name, info.get("role", role or "unassigned"))
                 for name, info in meta.get("unlabelled_files", {}).items()]
        source = "manifest"
    else:
        loose = []
        entries = []
        for p in sorted(root.glob("*.csv"), key=lambda p: (p.name.split("_part")[0], _part_number(p.name))):
            f2l_role = role_of_fleet_to_lab_file(p.name)
            if f2l_role is not None:
                entries.append((p, f2l_role))
        source = "fleet-to-lab names"
        if not entries and role is not None:
            entries = [(p, role) for p in sorted(root.glob("*.csv")) if not p.name.endswith(UNLABELLED_SUFFIX)]
            loose = [(p, role) for p in sorted(root.glob("*" + UNLABELLED_SUFFIX))]
            source = "role given by a roles file"
        if not entries and not loose:
            raise InputError(
                f"{root}: no {MANIFEST_NAME} and no files named like the Fleet-To-Lab originals "
                "(training_data_<leo_rover|cadre|husky>_<lunalab|default_moon>_..._partN.csv); a roles file that "
                "gives the folder a role takes every window CSV in it"
            )
    files, unlabelled = [], []
    for (path, file_role), out in [(e, files) for e in entries] + [(e, unlabelled) for e in loose]:
        if not path.exists():
            raise CsvFormatError(path, None, f"listed in {MANIFEST_NAME} but missing")
        if out is files:
            files.append(DataFile(path=path, role=file_role, table=read_windows_csv(path)))
        else:
            unlabelled.append(UnlabelledFile(path=path, role=file_role, features=read_unlabelled_csv(path)))
    return Dataset(root=root, files=files, source=source, unlabelled=unlabelled)


def write_manifest(root: Path, files: dict[str, dict], extra: dict) -> Path:
    """Write dataset.json mapping each file name to {'role': ..., ...}."""
    path = Path(root) / MANIFEST_NAME
    path.write_text(json.dumps({"format": MANIFEST_FORMAT, **extra, "files": files}, indent=2) + "\n")
    return path
