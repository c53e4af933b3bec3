"""Datasets: readers, the unified registry, batching and transforms."""

from trajpref.data.registry import ETH_UCY, NAMES, load_dataset, resolve_data_root

__all__ = ["ETH_UCY", "NAMES", "load_dataset", "resolve_data_root"]
