"""The head-path type, its interpolation and scripted paths: a thin face of :mod:`simulator.traces.path`.

Kept importable as the design names it; the code lives in ``simulator/traces/``.
"""

from simulator.traces.path import *
from simulator.traces.path import __all__  # noqa: F401
