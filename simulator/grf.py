"""The grain layout, the cutout and the opacity rule: a thin face of :mod:`simulator.mitigation.grf`.

Kept importable as the design names it; the code lives in ``simulator/mitigation/``.
"""

from simulator.mitigation.grf import *
from simulator.mitigation.grf import __all__  # noqa: F401
