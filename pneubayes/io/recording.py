"""Read, check and write recordings: the CSV + JSON interchange format.

``<stem>.csv`` holds the samples, ``<stem>.json`` what is known about the rig (the
contract is ``docs/recording-format.md``). Reading collects *every* problem and raises one
:class:`~pneubayes.errors.RecordingError` with ``(location, reason)`` pairs; a location
names the file and the row (1-based CSV line number, header = row 1) or the JSON key.

Rules: both files exist and are UTF-8 (a BOM is allowed). CSV: a header of unique,
non-empty names including ``time_s``, ``command_V``, ``pressure_Pa``; at least one data
row; every row as many fields as the header (blank lines only at the end); cells of
known columns are decimal numbers ('.' point), finite; time strictly increasing;
``pressure_Pa`` and ``supply_pressure_Pa`` > 0 Pa (absolute); ``|command_V|`` <= 5 V
+ ``COMMAND_TOLERANCE_V``. JSON: parses, an object without duplicate keys, every
required key; ``cylinder``, ``valve`` non-empty strings; bore, stroke, pressures and
temperature finite numbers > 0; supply > atmosphere; ``position_m``, if given, within
0..stroke. Unknown columns and keys are kept unvalidated (a column is float64 when every
cell is a number, else text). The ``position_m`` column is not bounded: a length sensor
reads slightly outside the stroke. The only normalisation: commands within the tolerance
are clipped to exactly +-5 V. Input files are only ever opened read-only.

Two versioned additions (README, "Recordings"): a JSON with ``"format":
"pneubayes-recording/2"`` may name columns and keys in declared units
(``pressure_kPa_gauge``, ``time_ms``, ``bore_mm``; :mod:`pneubayes.io.units`), converted
to the SI, absolute names before any check; and every reader then applies the
plausibility rules of :mod:`pneubayes.io.plausibility` (an error is a problem, warnings
stay in ``Recording.findings``; ``accept_unusual`` lists rules accepted for the file).

This module is the public face; the contract's names, the in-memory recording and the
value rules are in :mod:`~pneubayes.io.recording_format`, reading in
:mod:`~pneubayes.io.recording_read`, writing in :mod:`~pneubayes.io.recording_write`.
"""

from __future__ import annotations

from pneubayes.io.recording_format import (
    ACCEPT_KEY,
    COMMAND_LIMIT_V,
    COMMAND_TOLERANCE_V,
    FORMAT_1,
    FORMAT_2,
    FORMAT_KEY,
    OPTIONAL_COLUMNS,
    OPTIONAL_KEYS,
    REQUIRED_COLUMNS,
    REQUIRED_KEYS,
    Recording,
    RecordingMetadata,
    recording_paths,
)
from pneubayes.io.recording_read import (
    RecordingCheck,
    check_recording,
    inspect_recording,
    read_recording,
)
from pneubayes.io.recording_write import write_recording

__all__ = ["ACCEPT_KEY", "COMMAND_LIMIT_V", "COMMAND_TOLERANCE_V", "FORMAT_1", "FORMAT_2",
           "FORMAT_KEY", "OPTIONAL_COLUMNS", "OPTIONAL_KEYS", "REQUIRED_COLUMNS",
           "REQUIRED_KEYS", "Recording", "RecordingCheck", "RecordingMetadata",
           "check_recording", "inspect_recording", "read_recording", "recording_paths",
           "write_recording"]
