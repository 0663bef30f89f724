"""Restoration of the line-of-sight attitude from the images alone (patent claims 9–11, CNES §3).

Data flow (each a module): :mod:`.selection` → :mod:`.matching` →
:mod:`.synthesis` → :mod:`.axis_integration` (over :mod:`.integration`'s
methods) → anchoring and :mod:`.correction`; :mod:`.stages` wraps each step as a
function with explicit inputs and outputs, :class:`.restorer.Restorer` composes
them, :mod:`.pipeline` runs it on a run directory and :mod:`.restoration_io`
writes and reads ``restoration.nc``. Importing this package registers the
``[restoration]`` table in the scenario's validation pass.
"""
from .errors import RestorationError
from .restoration_io import read_restoration, restoration_dataset
from .restorer import Restorer
from .result import IntegrationRecord, PairData, RestorationResult
from .settings import RestorationSettings, restoration_settings

__all__ = ["Restorer", "RestorationSettings", "restoration_settings", "RestorationResult", "PairData",
           "IntegrationRecord", "RestorationError", "read_restoration", "restoration_dataset"]
