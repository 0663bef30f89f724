"""simsat — push-broom line-of-sight jitter simulator (Mitsuba 3) and restoration testbed.

The satellite and its world, one module per job (imported on use, so that
``import simsat`` stays light; the renderer loads Mitsuba only when rendering):

* :mod:`.scenario` — a TOML scenario, validated (:mod:`.config`, :mod:`.validation`);
* :mod:`.platform`, :mod:`.attitude`, :mod:`.instrument` — the platform's track,
  the line-of-sight attitude (jitter models, AOCS knowledge, star tracker), the
  focal plane and radiometry;
* :mod:`.terrain` — DEM, texture, illumination; :mod:`.render` — the Mitsuba
  push-broom renderer; :mod:`.sensor_model` — direct / inverse location;
* :mod:`.simulate` — scenario → run directory; :mod:`.product` — the files of a
  run (writer, lazy reader, atomic writes); :mod:`.rundir` — run directories,
  locks, provenance; :mod:`.units` — units and shared constants.

See docs/design.md for the data flow.
"""
__version__ = "0.1.0"

__all__ = ["__version__", "scenario", "config", "validation", "platform", "attitude", "instrument", "terrain",
           "render", "sensor_model", "simulate", "product", "rundir", "units"]
