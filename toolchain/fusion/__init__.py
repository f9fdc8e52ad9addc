"""Model fusion: Git Re-Basin alignment, AcoMerge, merging baselines."""
