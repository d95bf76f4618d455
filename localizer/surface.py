"""Height of the camera above the water surface, from either reference of the session format.

``takeoff_height_above_surface_m`` works with GLOBAL_POSITION_INT ``relative_alt``
(height above the take-off point, usually barometric); ``surface_amsl_m`` works with
``alt`` (above mean sea level, usually GNSS). Heights in metres, positive up.
"""

from __future__ import annotations

import numpy as np


def height_above_surface_m(
    alt_amsl_m,
    relative_alt_m,
    takeoff_height_above_surface_m=None,
    surface_amsl_m=None,
):
    """Height of the UAV's reported position above the water (exactly one reference set)."""
    if (takeoff_height_above_surface_m is None) == (surface_amsl_m is None):
        raise ValueError(
            "exactly one of takeoff_height_above_surface_m and surface_amsl_m is needed"
        )
    if surface_amsl_m is not None:
        return np.asarray(alt_amsl_m, dtype=float) - surface_amsl_m
    return np.asarray(relative_alt_m, dtype=float) + takeoff_height_above_surface_m
