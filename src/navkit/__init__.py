"""navkit: see, map, localize and come home without satellite navigation.

The four capabilities (each usable alone, NumPy arrays in and out):

- :mod:`navkit.obstacles` - isolated obstacles from range scans and the 2D obstacle map (paper 1);
- :mod:`navkit.planes` - planar objects, 6-DoF motion from 1, 2 or >= 3 textured planes (paper 2);
- :mod:`navkit.stereo` and :mod:`navkit.localization` - wall maps from a binocular camera and
  localization by correlation (paper 3);
- :mod:`navkit.path` - online spline memory of the odometry path and the return (paper 4);

on the shared core: :mod:`navkit.geometry`, :mod:`navkit.sensors`, :mod:`navkit.sim` (the built-in
simulated world), :mod:`navkit.io` (file formats) and :mod:`navkit.datasets`.
"""

import logging

from navkit._version import __version__
from navkit.errors import (
    ConfigError,
    DataNotFoundError,
    DegenerateGeometryError,
    FormatError,
    InputError,
    NavkitError,
    OptionalDependencyError,
)

logging.getLogger(__name__).addHandler(logging.NullHandler())

__all__ = [
    "ConfigError",
    "DataNotFoundError",
    "DegenerateGeometryError",
    "FormatError",
    "InputError",
    "NavkitError",
    "OptionalDependencyError",
    "__version__",
]
