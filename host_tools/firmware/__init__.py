"""The C firmware driver: CPU target discovery (`targets`), the one CMake/QEMU driver (`build`) and
`fleetlab bench c` (`bench`)."""
