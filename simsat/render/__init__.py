"""The only part of simsat that touches Mitsuba 3 / Dr.Jit.

* :func:`choose_variant` picks ``cuda_ad_mono`` when a GPU is usable, else
  ``llvm_ad_mono`` (override with ``SIMSAT_MITSUBA_VARIANT``).
* :mod:`.scene` builds the terrain mesh scene.
* :mod:`.pushbroom` renders a multi-band push-broom acquisition.
"""
from __future__ import annotations

import os

__all__ = ["choose_variant", "release_memory", "MITSUBA_FROM_LOCAL"]

#: Axis change between simsat's local frame and Mitsuba's world frame. simsat's
#: local frame (x along-track, y across-track, z up, metres, centred on the
#: scene) is used *as is* as Mitsuba's world frame: Mitsuba has no preferred
#: "up" for ray casting, so the change of axes is the identity. It is stated
#: here once so that any future change (e.g. y-up conventions) has one place.
MITSUBA_FROM_LOCAL = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))

_VARIANT: str | None = None


def choose_variant() -> str:
    """Select and return the Mitsuba variant (CUDA when available, else LLVM).

    The choice is made once per process. ``SIMSAT_MITSUBA_VARIANT`` forces a
    variant (e.g. ``llvm_ad_mono``).
    """
    global _VARIANT
    import mitsuba as mi

    if _VARIANT is not None:
        return _VARIANT
    forced = os.environ.get("SIMSAT_MITSUBA_VARIANT")
    candidates = [forced] if forced else ["cuda_ad_mono", "llvm_ad_mono"]
    errors = []
    for v in candidates:
        if v not in mi.variants():
            errors.append(f"{v}: not built in this Mitsuba")
            continue
        try:
            mi.set_variant(v)
            if v.startswith("cuda"):
                # a cheap kernel launch proves the driver works
                import drjit as dr
                dr.eval(mi.Float(1.0) + 1.0)
            _VARIANT = v
            return v
        except Exception as e:  # no GPU / no LLVM: try the next one
            errors.append(f"{v}: {e}".splitlines()[0])
    raise RuntimeError("no usable Mitsuba variant: " + "; ".join(errors))


def release_memory() -> None:
    """Give back the memory Dr.Jit keeps cached after a render (so later stages of one process start lean)."""
    import gc

    gc.collect()
    if _VARIANT is None:
        return
    import drjit as dr

    dr.sync_thread()
    dr.flush_malloc_cache()
