"""One viewing: its checked inputs, the plan of every frame, the job that renders it, the review video and eye frames.
"""

from simulator.viewing.job import (
    OUTDIR_FILES,
    REVIEW_FILES,
    VISIBLE_COLUMNS,
    render_viewing,
)

__all__ = [
    "OUTDIR_FILES",
    "REVIEW_FILES",
    "VISIBLE_COLUMNS",
    "render_viewing",
]
