"""Data layer: contracts, featurisation, labels, CSV I/O, dataset folders, splits, simulator."""
