"""The dataset layer: readings with named channels and units, images with unit, range and pixel size and/or
per-sample targets with units (labelled presses), splits and groups, per-sample extras, provenance; files
(format 3, formats 1 and 2 still read), shard folders of such files with a manifest, and import from plain
arrays and probe logs. numpy only: the simulator, the collection pipeline and the importers produce datasets,
training, evaluation and the commands consume them.

This folder also holds shipped data files (the measured DTact lookup tables and the interpolation fit).
"""

from tactile_manip.data.dataset import SPLITS, PairedDataset, concatenate
from tactile_manip.data.imports import from_arrays, read_array
from tactile_manip.data.probe_logs import PROBE_SPLITS, from_probe_logs
from tactile_manip.data.io import (DEPTH_RANGE_MM, DEPTH_SCALE_MM, FORMAT_VERSION, check_dataset_file, dataset_path,
                                   depth_image_spec, load_dataset, load_datasets, quantise_depth, save_dataset)
from tactile_manip.data.shards import ShardedDataset, ShardWriter, is_shard_folder, iter_shards, save_sharded
from tactile_manip.data.spec import CHANNEL_KINDS, ChannelSpec, ImageSpec
from tactile_manip.data.targets import STANDARD_TARGETS, target_from_label, target_unit

__all__ = ["CHANNEL_KINDS", "DEPTH_RANGE_MM", "DEPTH_SCALE_MM", "FORMAT_VERSION", "PROBE_SPLITS", "SPLITS", "ChannelSpec", "ImageSpec", "PairedDataset", "STANDARD_TARGETS", "ShardWriter", "ShardedDataset", "check_dataset_file", "concatenate", "dataset_path", "depth_image_spec",
           "from_arrays", "from_probe_logs", "is_shard_folder", "iter_shards", "load_dataset", "load_datasets", "quantise_depth", "read_array", "save_dataset", "save_sharded",
           "target_from_label", "target_unit"]
