"""The command line's cleaning of measured records: spikes, ``--despike``, ``--exclude``, a moving car's samples.

Every record `vehid identify` reads goes through :func:`clean_records` before it is prepared: its spikes
and drop-outs are found in every input, output and the speed (scheduling) channel
(:func:`~vehid.identification.dataio.cleaning.find_outliers`), replaced by interpolation with
``--despike``, the ``--exclude`` windows left out, and, for models that need a moving car
(``--structure single-track``, ``--schedule`` on a speed), the samples below ``--min-speed``; each
contiguous run of what is left is its own record, and the hold-out fraction is the last part of the
samples kept. What was found and done is in each record's metadata and becomes the JSON keys
``outliers``, ``despiked``, ``left_out`` and ``excluded``
(:func:`~vehid.identification.dataio.cleaning.cleaning_summary`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from vehid.identification.errors import InputError

if TYPE_CHECKING:  # the command line imports this module before it reads any data
    from vehid.identification.data import IOData
    from vehid.identification.dataio.cleaning import CleanedRecords

__all__ = ["MIN_SPEED", "MIN_RUN_SECONDS", "LEFT_OUT_SLOW", "parse_min_speed", "min_speed_of", "clean_records"]

#: The least speed (m/s) of the samples a model of a moving car is identified from, by default: below it a
#: rolling car's slip angles are not small (the single-track model's premise) and at standstill the speed
#: channel is noise about zero, negative as often as positive.
MIN_SPEED = 5.0
#: The shortest run of moving samples used as a record of a car's model (s): its states settle from an
#: unknown start within a few of its time constants (0.05-0.3 s at and above 5 m/s for a road car), so a
#: shorter run holds little to identify from after that.
MIN_RUN_SECONDS = 2.0
#: The key of ``left_out`` counting samples below the least speed.
LEFT_OUT_SLOW = "below_min_speed"


def parse_min_speed(text: Any) -> float | None:
    """``--min-speed``: a speed in the speed channel's units (after ``--scale``), or ``none`` to keep every sample."""
    if text is None:
        return None
    if isinstance(text, str) and text.strip().lower() == "none":
        return -math.inf
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise InputError(f"--min-speed takes a speed (m/s) or none; got {text!r}") from None
    if not math.isfinite(value):
        raise InputError(f"--min-speed takes a finite speed (m/s) or none; got {text!r}")
    return value


def min_speed_of(args: Any, moving_model: bool) -> float | None:
    """The least speed the run's records are cut at: ``--min-speed``, or :data:`MIN_SPEED` for a model that
    needs a moving car; None where no speed cuts them."""
    given = parse_min_speed(getattr(args, "min_speed", None))
    if given is None:
        return MIN_SPEED if moving_model else None
    return None if given == -math.inf else given


def clean_records(args: Any, records: Sequence[IOData], *, speeds: Sequence[np.ndarray] | None = None,
                  speed_name: str | None = None, speed_factor: float = 1.0, min_speed: float | None = None,
                  holdout: float | None = None, speed_in_record: bool = False) -> CleanedRecords:
    """Each record cleaned and cut into runs (module docstring), the runs of all records in order.

    Parameters
    ----------
    args : argparse.Namespace
        ``--despike`` and ``--exclude``.
    records : sequence of IOData
        As read, in the file's units.
    speeds : sequence of ndarray, optional
        The speed (or scheduling) channel of each record, as read.
    speed_name : str, optional
        Its name, for the outliers list.
    speed_factor : float
        Its ``--scale`` factor to m/s; the runs' speeds (``extra_estimation`` and ``extra_validation``
        under ``speed_name``) are returned scaled.
    min_speed : float, optional
        Samples below it are left out (:func:`min_speed_of`); runs shorter than :data:`MIN_RUN_SECONDS`
        (and :data:`~vehid.identification.dataio.cleaning.MIN_RUN_SAMPLES`) are dropped.
    holdout : float, optional
        The fraction of each record's kept samples held out, at its end.
    speed_in_record : bool
        The speed is one of the records' own channels (searched and cut with them), not a channel beside
        them: no runs' speeds are returned.
    """
    from vehid.identification.dataio import cleaning
    from vehid.identification.dataio.timewindow import parse_time_windows

    keeps = None
    if min_speed is not None:
        if speeds is None:
            raise InputError("--min-speed needs the speed channel: give --schedule CHANNEL")
        keeps = []
        for record, speed in zip(records, speeds):
            scaled = np.asarray(speed, dtype=float) * speed_factor
            if not np.any(scaled >= min_speed):
                raise InputError(f"{record.meta.get('source', 'the record')}: the speed channel {speed_name!r} never "
                                 f"reaches --min-speed {min_speed:g} (it runs from {scaled.min():.4g} to "
                                 f"{scaled.max():.4g}): is it in m/s, forwards positive? (convert with --scale)")
            keeps.append(scaled >= min_speed)
    beside = speeds is not None and not speed_in_record
    name = speed_name or "speed"
    cleaned = cleaning.clean_records(
        records, extras=[{name: speed} for speed in speeds] if beside else None, keeps=keeps,
        min_run_samples=[max(cleaning.MIN_RUN_SAMPLES, math.ceil(MIN_RUN_SECONDS / record.dt)) if keeps else
                         cleaning.MIN_RUN_SAMPLES for record in records],
        despike_outliers=bool(getattr(args, "despike", False)),
        exclude=parse_time_windows(getattr(args, "exclude", None)), left_out_as=LEFT_OUT_SLOW, holdout=holdout)
    if not beside:
        return cleaned
    return dataclasses.replace(cleaned, **{f"extra_{side}": {name: tuple(part * speed_factor for part in parts[name])}
                                           for side, parts in (("estimation", cleaned.extra_estimation),
                                                               ("validation", cleaned.extra_validation))})
