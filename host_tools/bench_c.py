"""`fleetlab bench c` lives in `fleetlab.host_tools.firmware.bench`; this name is kept for the CLI table
and for callers of the old module."""

from .firmware.bench import (  # noqa: F401
    DEFAULT_BUNDLE, REPO, add_arguments, host_timings, library_footprint, parse_kv, run, target_costs,
    target_figures,
)
from .firmware.build import cmake_build as _cmake_build


def cmake_build(build_dir, bundle, *, cpu=None, options=None, jobs=2):
    """Old signature (cpu=<target name>) of `firmware.build.cmake_build`."""
    return _cmake_build(build_dir, bundle, target=cpu, options=options, jobs=jobs)
