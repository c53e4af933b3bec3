"""Datasets: readers, the unified registry, batching and transforms."""

from trajpref.data.registry import (
    ETH_UCY,
    NAMES,
    PROTOCOLS,
    add_paced_copy,
    apply_protocol,
    hold_out_scene,
    load_dataset,
    resolve_data_root,
    run_splits,
    split_validation_in_time,
    with_paced_copy,
)
from trajpref.data.stats import mean_speed, speed_note, speed_text
from trajpref.data.text import GapWarning, ReadOptions
from trajpref.data.tracker import LeftOutWarning, TrackHistory, tracks_to_history
from trajpref.data.trajnet import FrameRateWarning, write_trajnet, write_trajnet_truth

__all__ = [
    "ETH_UCY",
    "FrameRateWarning",
    "NAMES",
    "PROTOCOLS",
    "GapWarning",
    "LeftOutWarning",
    "ReadOptions",
    "TrackHistory",
    "add_paced_copy",
    "apply_protocol",
    "hold_out_scene",
    "load_dataset",
    "mean_speed",
    "resolve_data_root",
    "run_splits",
    "speed_note",
    "speed_text",
    "split_validation_in_time",
    "tracks_to_history",
    "with_paced_copy",
    "write_trajnet",
    "write_trajnet_truth",
]
