"""Mitigations: the grain layout, cutout and opacity rule (``grf``), and what is drawn over the video with the flow still reaching the eye (``kinds``).
"""

from simulator.mitigation.kinds import (
    Mitigation,
    VisibleFlow,
    cell_opacity,
    parse_color,
    visible_flow,
)

__all__ = [
    "Mitigation",
    "VisibleFlow",
    "cell_opacity",
    "parse_color",
    "visible_flow",
]
