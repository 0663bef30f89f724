"""Units and shared constants, with names that say which way a factor goes.

simsat computes in SI (angles in rad, times in s, lengths in m); µrad and
pixels are for people (scenario keys, tables, plots). Multiply by
``RAD_PER_URAD`` to go from µrad to rad, by ``URAD_PER_RAD`` from rad to µrad.
"""
from __future__ import annotations

__all__ = ["AXES", "RAD_PER_URAD", "URAD_PER_RAD", "urad", "to_urad"]

#: the line-of-sight attitude axes, in the order of every (…, 3) array
AXES = ("roll", "pitch", "yaw")

#: one microradian in radians (µrad → rad)
RAD_PER_URAD = 1e-6
#: microradians in one radian (rad → µrad)
URAD_PER_RAD = 1e6


def urad(value):
    """An angle given in µrad, in rad."""
    return value * RAD_PER_URAD


def to_urad(value_rad):
    """An angle given in rad, in µrad."""
    return value_rad * URAD_PER_RAD
