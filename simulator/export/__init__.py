"""Export for game engines: the POF matrix or the sphere-mode field with a runtime (Unity, C#).

:mod:`simulator.export.unity` writes ``vimsim_epof.bin`` (a little-endian binary with a JSON
header: flow, grain layout, GRF and vignette settings, range) and a Unity package around it
(the C# runtime, the overlay shader, a prefab, an importer; the files shipped in
``simulator/export/unity/``); ``docs/unity.md`` documents the layout and the calls.
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
