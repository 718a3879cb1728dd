"""The headless GL renderer: GL set-up, the eye renderer, and whole per-eye videos.

The stage's public names are re-exported here (``from simulator.render import ...``); each
submodule says what it holds.
"""

from __future__ import annotations

from simulator.render.eye import EyeRenderer, RenderConfig, render_view
from simulator.render.gl import EGL_PACKAGES, ShaderError, create_context, load_shader_source
from simulator.render.video import VideoRenderResult, render_video

__all__ = [
    "EGL_PACKAGES",
    "EyeRenderer",
    "RenderConfig",
    "ShaderError",
    "VideoRenderResult",
    "create_context",
    "load_shader_source",
    "render_video",
    "render_view",
]
