"""One viewing: what the eye sees, its checked inputs, the plan of every frame, the job that renders it, the review video and eye frames."""

from simulator.viewing.job import (
    OUTDIR_FILES,
    REVIEW_FILES,
    VISIBLE_COLUMNS,
    render_viewing,
)
from simulator.viewing.spec import VIEW_OPTIONS, ViewSpec

__all__ = [
    "OUTDIR_FILES",
    "REVIEW_FILES",
    "VIEW_OPTIONS",
    "VISIBLE_COLUMNS",
    "ViewSpec",
    "render_viewing",
]
