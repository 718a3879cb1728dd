"""EPOF: the optical flow a viewer sees, from a grid and a head path, by window overlaps (paper) or exactly (sphere).

The stage's public names are re-exported here (``from simulator.epof import ...``); each
submodule says what it holds.
"""

from __future__ import annotations

from simulator.epof.exact import ViewportQuery, viewport_epof
from simulator.epof.overlaps import (
    ViewportOverlaps,
    epof_from_grid,
    viewport_overlaps,
    weighted_epof,
)
from simulator.epof.viewing import (
    EPOF_COLUMNS,
    EpofResult,
    compute_epof,
    plot_epof,
    read_epof_csv,
    write_epof_csv,
)

__all__ = [
    "EPOF_COLUMNS",
    "EpofResult",
    "ViewportOverlaps",
    "ViewportQuery",
    "compute_epof",
    "epof_from_grid",
    "plot_epof",
    "read_epof_csv",
    "viewport_epof",
    "viewport_overlaps",
    "weighted_epof",
    "write_epof_csv",
]
