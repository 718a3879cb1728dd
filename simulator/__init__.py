"""vimsim: viewport-aware optical flow in 360-degree video and optical-flow-driven
granulated rest frames (GRFs), headless.

Conventions (written once in :mod:`simulator.sphere.geometry`, repeated in every docstring):
angles in degrees at every boundary (``*_deg``), radians inside; world frame
+x right, +y up, +z forward (lon = 0, lat = 0); head yaw (+ right), pitch (+ up),
roll (+ right ear down), applied yaw, then pitch, then roll (intrinsic).
"""

from simulator.core.errors import InputError, VimsimError

__version__ = "0.1.0"
__all__ = ["InputError", "VimsimError", "__version__"]
