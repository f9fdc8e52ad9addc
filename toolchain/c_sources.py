"""What of the source tree the C build needs, and a copy of it for a firmware build.

One list for both users: setup.py puts these files into the wheel (fleetlab/c_tree, the same layout), and
`fleetlab c-sources --out DIR` copies them out of the clone or the wheel for an integrator's own CMake
build (`add_subdirectory(DIR slipest EXCLUDE_FROM_ALL)`). Standard library only: setup.py runs this file
before fleetlab is installed.
"""

from __future__ import annotations

import shutil
from fnmatch import fnmatch
from pathlib import Path

# paths relative to the tree's root: CMakeLists.txt and everything it, the CPU target files, the generators it
# runs (DBC layout check, object-dictionary generator), the example bundle, the fuzz and Frama-C drivers
# (firmware_c/fuzz, firmware_c/eva) and the export helper's C vector checker read
C_TREE = (
    "CMakeLists.txt",
    "firmware_c",
    "dbc/slipest.dbc",
    "dbc/layout.py",
    "canopen_od/__init__.py",
    "canopen_od/objects.py",
    "canopen_od/generate.py",
    "export/c",
    "scripts/apt-packages.txt",  # the Debian package of each tool (fleetlab.system_tools, target.cmake)
)
# build and analysis leftovers, never sources (cppcheck leaves *.dump / *.ctu-info beside the files it read)
_SKIP = ("*.pyc", "*.o", "*.a", "*.so", "*.dump", "*.ctu-info")


def tree_files(root: Path) -> list[Path]:
    """Every file of C_TREE under `root`, relative to it (sorted); OSError naming a missing entry."""
    out: list[Path] = []
    for entry in C_TREE:
        path = Path(root) / entry
        if path.is_file():
            out.append(Path(entry))
        elif path.is_dir():
            for f in sorted(path.rglob("*")):
                if f.is_file() and "__pycache__" not in f.parts and not any(fnmatch(f.name, p) for p in _SKIP):
                    out.append(f.relative_to(root))
        else:
            raise OSError(f"{path}: missing from the C source tree")
    return sorted(out)


def copy_tree(root: Path, dest: Path) -> list[Path]:
    """Copy C_TREE from `root` into `dest` (same layout); returns the files written, relative to `dest`."""
    files = tree_files(root)
    for rel in files:
        target = Path(dest) / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(Path(root) / rel, target)
    return files
