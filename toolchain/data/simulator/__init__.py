"""Simulated rover telemetry: terramechanics, rovers, terrains, driver, sensors, scenarios."""
