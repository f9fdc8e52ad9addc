"""Flight-software assurance evidence for the slipest C library (issue 16).

One module per kind of evidence: ``misra`` (cppcheck MISRA C:2012 addon against the recorded
deviations), ``analysers`` (clang-tidy, gcc -fanalyzer, strict warnings, Frama-C EVA),
``coverage`` (gcov statement/branch), ``stack`` (worst-case stack from GCC's call-graph
files, no-recursion proof), ``wcet`` (Cortex-M4 instruction counts under QEMU) and
``report`` (``fleetlab assure``: runs them all and writes one markdown + HTML report).
The layer sits above export, beside host_tools: it reads bundles and the C sources only.
"""
