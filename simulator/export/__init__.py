"""Export for game engines: the POF matrix or the sphere-mode field with a runtime (Unity, C#).

:mod:`simulator.export.unity` writes ``vimsim_epof.bin`` (a little-endian binary with a JSON
header) and the C# runtime shipped in ``simulator/export/unity/*.cs``; ``docs/unity.md``
documents the layout and the calls.
"""

from simulator.export.unity import (
    DATA_FILE,
    FORMAT,
    VERSION,
    ExportResult,
    export_unity,
    frame_at,
    read_export,
)

__all__ = [
    "DATA_FILE",
    "FORMAT",
    "VERSION",
    "ExportResult",
    "export_unity",
    "frame_at",
    "read_export",
]
