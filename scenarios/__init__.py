"""Studies that wire the vehicle model and the identification methods together, and the ``vehid`` CLI.

What the commands do is a library function first, each returning a frozen result that renders the
command's JSON (``render()``) and text (``text()``): :func:`vehid.identification.identify` (`vehid
identify`), :func:`identify_single_track` (`vehid identify --structure single-track`),
:func:`handling` (`vehid handling`) and :func:`calibrate` (`vehid calibrate`); the command line in :mod:`vehid.scenarios.commands` maps its
arguments to their options and prints the result.
"""

from ._parent_watch import watch_if_worker as _watch_if_worker

_watch_if_worker()  # first of all: a worker whose parent dies while it starts up must not outlive it

from vehid.identification.lazy_exports import export_lazily  # noqa: E402  (after the watch, as everything else)

# submodule -> the public names it defines, each imported when first asked for
_EXPORTS: dict[str, tuple[str, ...]] = {
    "single_track_identify": ("identify_single_track", "SingleTrackOptions", "SingleTrackIdentification", "Estimate"),
    "car_handling": ("handling", "HandlingOptions", "SourceHandlingOptions", "ModelHandling",
                         "SourceModelHandling"),
    "car_calibration": ("calibrate", "CalibrateOptions", "CalibrationResult"),
    "plausibility_checks": ("CarChecks",),
}
export_lazily(__name__, _EXPORTS)

__all__ = ["identify_single_track", "SingleTrackOptions", "SingleTrackIdentification", "Estimate", "handling",
           "HandlingOptions", "SourceHandlingOptions", "ModelHandling", "SourceModelHandling", "calibrate",
           "CalibrateOptions", "CalibrationResult", "CarChecks"]
