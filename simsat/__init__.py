"""simsat — push-broom line-of-sight jitter simulator (Mitsuba 3) and restoration testbed.

The satellite and its world: terrain, platform, attitude, instrument, the
sensor model (direct / inverse location), the Mitsuba push-broom renderer and
the product format. See docs/design.md for the data flow.
"""
__version__ = "0.1.0"
