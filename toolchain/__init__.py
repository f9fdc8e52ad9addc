"""fleetlab: lunar-rover wheel-slip estimation from fleet data to a rover CPU."""

__version__ = "0.1.0"
