"""Datasets: the registry, downloads and checksums, views (window, segment, rate), splits, plugins' datasets."""
