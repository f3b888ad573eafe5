"""`vehid identify` from Python under its former name: :func:`vehid.identification.identify`.

The pipeline lives in :mod:`vehid.identification.pipeline` (and its parts in
:mod:`vehid.identification.automatic`); code importing :func:`identify` from
here keeps working.
"""

from vehid.identification.pipeline import identify

__all__ = ["identify"]
