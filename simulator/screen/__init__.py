"""Screening videos before anyone watches them: scripted viewers, flow bands, artefacts left out."""

from simulator.screen.run import SCREEN_COLUMNS, screen_videos

__all__ = ["SCREEN_COLUMNS", "screen_videos"]
