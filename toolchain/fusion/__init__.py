"""Model fusion: Git Re-Basin alignment, AcoMerge, merging baselines, and the registry of
fusion methods by name (`registry`), which holds the paper's methods (`methods`) from here on."""

from . import methods as _paper_methods  # noqa: F401  (registers them)
