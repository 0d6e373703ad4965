"""Reading and writing measured data in the project's interchange format."""

from pneubayes.io.preprocess import (
    despike_pressure,
    prepare_recording,
    smooth_inputs,
    smooth_position,
    smooth_supply,
)
from pneubayes.io.recording import (
    COMMAND_LIMIT_V,
    COMMAND_TOLERANCE_V,
    Recording,
    RecordingMetadata,
    check_recording,
    inspect_recording,
    read_recording,
    recording_paths,
    write_recording,
)

__all__ = [
    "COMMAND_LIMIT_V",
    "COMMAND_TOLERANCE_V",
    "Recording",
    "RecordingMetadata",
    "check_recording",
    "despike_pressure",
    "inspect_recording",
    "prepare_recording",
    "read_recording",
    "recording_paths",
    "smooth_inputs",
    "smooth_position",
    "smooth_supply",
    "write_recording",
]
