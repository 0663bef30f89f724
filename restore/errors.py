"""Errors of the restoration."""
from __future__ import annotations

__all__ = ["RestorationError"]


class RestorationError(RuntimeError):
    """Restoration cannot proceed (e.g. no usable texture); the message says why."""
