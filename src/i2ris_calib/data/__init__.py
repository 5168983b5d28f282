"""The data layer: a synced recording -> motion-direction datasets over the whole history."""

from i2ris_calib.data.dataset import (
    AXES,
    DIRECTIONS,
    Bands,
    Dataset,
    direction_datasets,
    direction_input,
    direction_of_samples,
    input_bands,
    make_dataset,
)

__all__ = [
    "AXES",
    "DIRECTIONS",
    "Bands",
    "Dataset",
    "direction_datasets",
    "direction_input",
    "direction_of_samples",
    "input_bands",
    "make_dataset",
]
