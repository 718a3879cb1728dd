"""vimsim: viewport-aware optical flow in 360-degree video and optical-flow-driven
granulated rest frames (GRFs), headless.

Conventions (written once in :mod:`simulator.sphere.geometry`, repeated in every docstring):
angles in degrees at every boundary (``*_deg``), radians inside; world frame
+x right, +y up, +z forward (lon = 0, lat = 0); head yaw (+ right), pitch (+ up),
roll (+ right ear down), applied yaw, then pitch, then roll (intrinsic).

The top-level API (each name is imported on first use, PEP 562, so that
``python -m simulator --help`` starts without numpy):

* :func:`preprocess_video` (paper mode, the POF matrix, over the windows of
  :func:`grid_preset`) / :func:`preprocess_sphere` (sphere mode): a video's grid file;
* :func:`load_grid`: a grid file; :func:`load_headpath`: a head path in any format
  ``vimsim headpath`` reads;
* :func:`compute_epof`: a viewing's EPOF and GRF opacity;
* :func:`render_viewing`: what each eye saw, into a folder (``vimsim render``), with
  :class:`ViewSpec` (what the eye sees) and :class:`Source` (the video).
"""

import importlib

from simulator.core.errors import InputError, VimsimError

__version__ = "0.1.0"

#: The lazy names and the module each comes from.
_API = {
    "preprocess_video": "simulator.preprocess.paper",
    "preprocess_sphere": "simulator.preprocess.sphere",
    "load_grid": "simulator.media.gridfile",
    "load_headpath": "simulator.traces.readers",
    "compute_epof": "simulator.epof.viewing",
    "render_viewing": "simulator.viewing.job",
    "ViewSpec": "simulator.viewing.spec",
    "Source": "simulator.media.source",
    "grid_preset": "simulator.sphere.windows",
}

__all__ = [
    "InputError",
    "Source",
    "ViewSpec",
    "VimsimError",
    "__version__",
    "compute_epof",
    "grid_preset",
    "load_grid",
    "load_headpath",
    "preprocess_sphere",
    "preprocess_video",
    "render_viewing",
]


def __getattr__(name: str):
    """Import an API name on first use (PEP 562) and keep it."""
    module = _API.get(name)
    if module is None:
        raise AttributeError(f"module 'simulator' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_API})
