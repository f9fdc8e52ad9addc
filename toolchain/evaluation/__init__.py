"""Monte Carlo cross-validation, metrics, statistics, tables and plots."""
