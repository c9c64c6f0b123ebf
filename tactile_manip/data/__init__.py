"""The paired dataset layer: readings with named channels and units, images with unit, range and pixel
size, splits and groups, per-sample extras, provenance; files (format 2, format 1 still read) and import
from plain arrays. numpy only: the simulator and the collection pipeline produce datasets, training,
evaluation and the commands consume them.

This folder also holds shipped data files (the measured DTact lookup tables and the interpolation fit).
"""

from tactile_manip.data.dataset import SPLITS, PairedDataset, concatenate
from tactile_manip.data.imports import from_arrays, read_array
from tactile_manip.data.io import (DEPTH_RANGE_MM, DEPTH_SCALE_MM, FORMAT_VERSION, check_dataset_file, dataset_path,
                                   depth_image_spec, load_dataset, load_datasets, quantise_depth, save_dataset)
from tactile_manip.data.spec import CHANNEL_KINDS, ChannelSpec, ImageSpec

__all__ = ["CHANNEL_KINDS", "DEPTH_RANGE_MM", "DEPTH_SCALE_MM", "FORMAT_VERSION", "SPLITS", "ChannelSpec", "ImageSpec", "PairedDataset", "check_dataset_file", "concatenate", "dataset_path", "depth_image_spec",
           "from_arrays", "load_dataset", "load_datasets", "quantise_depth", "read_array", "save_dataset"]
