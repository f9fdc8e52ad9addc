"""Packaging beyond pyproject.toml: the wheel carries the C source tree (toolchain/c_sources.py lists it) as
fleetlab/c_tree, so that an installed fleetlab builds and runs the C estimator without a clone."""

import runpy
import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
c_sources = runpy.run_path(str(ROOT / "toolchain" / "c_sources.py"))


class BuildPyWithCTree(build_py):
    def run(self):
        super().run()
        if not getattr(self, "editable_mode", False):  # an editable install reads the clone itself
            dest = Path(self.build_lib) / "fleetlab" / "c_tree"
            shutil.rmtree(dest, ignore_errors=True)  # build_lib outlives a build: no file of an earlier one stays
            c_sources["copy_tree"](ROOT, dest)


setup(cmdclass={"build_py": BuildPyWithCTree},
      # setuptools' own build folder, apart from build/, where the CMake builds of a clone go
      options={"build": {"build_base": "build/python"}})
