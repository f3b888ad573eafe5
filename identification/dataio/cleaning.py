"""Samples a record should not be identified from: spikes and drop-outs, stretches left out, runs too short.

* **Spikes and drop-outs** (:func:`find_outliers`): a Hampel filter on every channel. A sample is an
  outlier where it departs from the median of the :data:`WINDOW` samples centred on it by more than
  :data:`THRESHOLD` scaled MADs (1.4826 times the median absolute deviation of those samples from their
  median: the standard deviation, for Gaussian noise). Near the ends the window is mirrored about the end
  sample. The scale is floored at the channel's typical departure from its moving median (the median of
  the departures over the whole channel, scaled alike) and at the channel's resolution (its smallest
  step between samples), so that a stretch the logger held constant, or a binary signal, does not turn
  its smallest step into an outlier. The departure must also exceed :data:`SIZE_SHARE` of the channel's
  span (1st to 99th percentile): a smooth channel's MAD is tiny, and its small bumps (a speed's 0.05 m/s
  at 61 m/s) are no glitch a fit or a figure would notice. A run of up to :data:`HALF_WIDTH` flagged
  samples is a spike or a drop-out; anything wider moves the median with it and is the signal itself.
  The threshold is far above Gaussian noise (a 20-sigma departure has probability 5.5e-89) and twice a
  car's vibration: on the 550 s race-car drive, of the samples departing by more than a tenth of their
  channel's span, the accelerometers' depart by at most 9.2 scaled MADs and no other channel's but the
  steer's by any, while its four one-sample steer glitches depart by 142 to 1,199
  (docs/measured_data.md, "Spikes and drop-outs").
* **Repair** (:func:`despike`): each outlier replaced by the straight line between the nearest samples
  of its channel that are not outliers.
* **Runs** (:func:`clean_record`): the samples to use (outside ``--exclude`` windows, and where a
  caller's mask says, a moving car's) as records, one per contiguous run; runs shorter than a stated
  number of samples are dropped and counted. What was found and done goes into each run's
  ``meta["cleaning"]`` (so an archive keeps it) and into the JSON keys of :func:`cleaning_summary`.

This module knows records and channels, not what they measure: a caller that knows (a car's speed)
builds the mask.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from ..data import IOData
from ..errors import InputError
from .timewindow import TimeWindow, time_text, window_mask

__all__ = ["HALF_WIDTH", "WINDOW", "THRESHOLD", "SIZE_SHARE", "MAD_TO_STD", "MIN_RUN_SAMPLES", "Outlier",
           "hampel_departures", "hampel_outliers", "find_outliers", "despike", "exclusion_mask", "CleanedRecord",
           "clean_record", "CleanedRecords", "clean_records", "cleaning_summary", "cleaning_warnings",
           "cleaning_notes", "record_file_time"]

#: Samples on each side of the sample judged: the Hampel window is ``2 HALF_WIDTH + 1`` samples long, and a
#: spike or drop-out is at most ``HALF_WIDTH`` samples wide.
HALF_WIDTH = 5
#: The Hampel window's length in samples.
WINDOW = 2 * HALF_WIDTH + 1
#: Scaled MADs beyond which a sample is an outlier (module docstring: why so far out).
THRESHOLD = 20.0
#: Share of a channel's span (its 1st to 99th percentile) a departure must also exceed: smaller ones move
#: neither a fit nor a figure's range, and a smooth channel's small bumps depart by many of its tiny MADs.
SIZE_SHARE = 0.1
#: The median absolute deviation of Gaussian noise times this is its standard deviation.
MAD_TO_STD = 1.4826


@dataclass(frozen=True)
class Outlier:
    """One sample of one channel found to be a spike or a drop-out.

    Attributes
    ----------
    channel : str
    index : int
        The sample's index in the record.
    time : float
        Its time in the file's own time base (s): the record's time plus its ``time_offset``.
    value : float
        Its value as read, in the file's units.
    departure : float
        How far it departs from its moving median, in scaled MADs.
    """

    channel: str
    index: int
    time: float
    value: float
    departure: float

    def as_dict(self) -> dict[str, Any]:
        """The JSON form (``{channel, time, value}``, and how far it departs)."""
        return {"channel": self.channel, "time": round(self.time, 6), "value": self.value,
                "departure_mads": self.departure}


def _moving_median_and_mad(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each sample's window median and scaled MAD, the window mirrored about the end samples."""
    from numpy.lib.stride_tricks import sliding_window_view

    reach = min(HALF_WIDTH, values.size - 1)
    padded = np.concatenate([values[reach:0:-1], values, values[-2:-reach - 2:-1]])
    windows = sliding_window_view(padded, 2 * reach + 1)
    median = np.median(windows, axis=1)
    mad = MAD_TO_STD * np.median(np.abs(windows - median[:, None]), axis=1)
    return median, mad


def hampel_departures(values: Any) -> tuple[np.ndarray, np.ndarray]:
    """Each sample's departure from its moving median in scaled MADs (the scale floored as the module
    docstring says), and whether it departs by more than :data:`SIZE_SHARE` of the channel's span.

    Parameters
    ----------
    values : array_like (N,)

    Returns
    -------
    scaled : ndarray (N,)
    large : ndarray of bool (N,)
    """
    values = np.asarray(values, dtype=float).ravel()
    if values.size < 3:
        return np.zeros(values.size), np.zeros(values.size, dtype=bool)
    median, mad = _moving_median_and_mad(values)
    departure = np.abs(values - median)
    steps = np.abs(np.diff(values))
    moving = steps[steps > 0]
    resolution = float(np.min(moving)) if moving.size else 0.0
    # rounding of the values themselves is never an outlier
    floor = max(MAD_TO_STD * float(np.median(departure)), resolution, 1e-12 * float(np.max(np.abs(values))))
    if floor == 0.0:  # a constant channel
        return np.zeros(values.size), np.zeros(values.size, dtype=bool)
    span = float(np.percentile(values, 99) - np.percentile(values, 1))
    return departure / np.maximum(mad, floor), departure > SIZE_SHARE * span


def hampel_outliers(values: Any) -> tuple[np.ndarray, np.ndarray]:
    """The indices of a channel's spikes and drop-outs (module docstring), and each one's departure in scaled MADs.

    Parameters
    ----------
    values : array_like (N,)

    Returns
    -------
    indices : ndarray of int
    departures : ndarray of float
    """
    scaled, large = hampel_departures(values)
    flagged = np.flatnonzero((scaled > THRESHOLD) & large)
    return flagged, scaled[flagged]


def record_file_time(record: IOData) -> np.ndarray:
    """The record's sample times in the file's own time base (its time plus ``meta["time_base"]["time_offset"]``)."""
    offset = float(record.meta.get("time_base", {}).get("time_offset", 0.0) or 0.0)
    return record.t + offset


def find_outliers(record: IOData, extra: Mapping[str, Any] | None = None) -> tuple[Outlier, ...]:
    """Spikes and drop-outs in every input and output of a record (:func:`hampel_outliers`), in time order.

    Parameters
    ----------
    record : IOData
        As read (in the file's units).
    extra : mapping of str to array_like (N,), optional
        Further channels the identification uses, read beside the record (a scheduling channel).
    """
    times = record_file_time(record)
    channels = [*zip(record.input_names, record.u.T), *zip(record.output_names, record.y.T),
                *((name, np.asarray(values, dtype=float)) for name, values in (extra or {}).items())]
    found = []
    for name, values in channels:
        if np.shape(values) != (record.n_samples,):
            raise InputError(f"channel {name!r} has {np.size(values)} samples; the record has {record.n_samples}")
        indices, departures = hampel_outliers(values)
        found += [Outlier(name, int(k), float(times[k]), float(values[k]), float(d))
                  for k, d in zip(indices, departures)]
    return tuple(sorted(found, key=lambda outlier: (outlier.index, outlier.channel)))


def _interpolated(values: np.ndarray, bad: np.ndarray) -> np.ndarray:
    good = np.flatnonzero(~bad)
    repaired = values.copy()
    repaired[bad] = np.interp(np.flatnonzero(bad), good, values[good])
    return repaired


def despike(record: IOData, outliers: Sequence[Outlier]) -> IOData:
    """The record with each outlier of its inputs and outputs replaced by the straight line between the
    nearest samples of its channel that are not outliers (at an end: the nearest such sample)."""
    columns = {"u": record.u.copy(), "y": record.y.copy()}
    places = {name: ("u", i) for i, name in enumerate(record.input_names)}
    places.update({name: ("y", i) for i, name in enumerate(record.output_names)})
    masks: dict[str, np.ndarray] = {}
    for outlier in outliers:
        if outlier.channel in places:
            masks.setdefault(outlier.channel, np.zeros(record.n_samples, dtype=bool))[outlier.index] = True
    for name, bad in masks.items():
        kind, column = places[name]
        if bad.all():
            raise InputError(f"every sample of {name!r} is an outlier: nothing to interpolate from")
        columns[kind][:, column] = _interpolated(columns[kind][:, column], bad)
    return record.replace(**columns)


#: The least run of kept samples used as a record where the caller states none: the filter settles each
#: record's unknown start over up to a quarter of it, and the data start needs a few dozen samples per order.
MIN_RUN_SAMPLES = 50


def exclusion_mask(record: IOData, windows: Sequence[TimeWindow]) -> tuple[np.ndarray, list[dict[str, Any]]]:
    """Which samples lie outside every window, and per window its text and how many samples it left out.

    Windows are in the file's time or from the log's first sample (``+T0:+T1``: the file's first sample,
    before any ``--segment``; ``meta["time_base"]["log_start"]``).
    """
    base = record.meta.get("time_base", {})
    offset = float(base.get("time_offset", 0.0) or 0.0)
    log_start = base.get("log_start")
    keep = np.ones(record.n_samples, dtype=bool)
    rows = []
    for window in windows:
        inside = window_mask(record.t, window, offset, None if log_start is None else float(log_start))
        rows.append({"window": str(window), "samples": int(np.count_nonzero(inside))})
        keep &= ~inside
    return keep, rows


@dataclass(frozen=True, eq=False)
class CleanedRecord:
    """A record's runs of usable samples as records, its outliers and what was left out.

    Attributes
    ----------
    estimation, validation : tuple of IOData
        The runs before and after the hold-out cut, each with ``meta["run"]`` (its first and last
        sample in the record) and ``meta["cleaning"]`` (:attr:`report`).
    validation_follows : tuple of int
        For each validation run, the estimation run it continues (the last before the cut).
    extra_estimation, extra_validation : dict of str to tuple of ndarray
        The extra channels (a scheduling channel), cut alike.
    report : dict
        What was found and done (docs/measured_data.md, "Spikes and drop-outs" and "A moving car's
        samples"; the JSON keys of :func:`cleaning_summary`).
    """

    estimation: tuple[IOData, ...]
    validation: tuple[IOData, ...]
    validation_follows: tuple[int, ...]
    extra_estimation: dict[str, tuple[np.ndarray, ...]]
    extra_validation: dict[str, tuple[np.ndarray, ...]]
    report: dict[str, Any]


def _runs(keep: np.ndarray) -> list[tuple[int, int]]:
    """The (start, stop) index pairs of the runs of True in ``keep``."""
    edges = np.diff(np.concatenate([[0], keep.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist()))


def clean_record(
    record: IOData,
    *,
    extra: Mapping[str, Any] | None = None,
    despike_outliers: bool = False,
    exclude: Sequence[TimeWindow] = (),
    keep: Any = None,
    left_out_as: str = "left_out_by_caller",
    min_run_samples: int = MIN_RUN_SAMPLES,
    holdout: float | None = None,
) -> CleanedRecord:
    """Find a record's outliers, repair them where asked, and cut it into runs of the samples to use.

    In this order: outliers of every channel (:func:`find_outliers`, on the whole record, extra channels
    too); with ``despike_outliers`` each replaced by interpolation (:func:`despike`); the samples in an
    ``exclude`` window or outside ``keep`` left out; the hold-out cut, so that the last ``holdout`` of the
    samples kept is validation data; each part's runs of kept samples as records, those shorter than
    ``min_run_samples`` dropped.

    Parameters
    ----------
    record : IOData
        As read, in the file's units.
    extra : mapping of str to array_like (N,), optional
        Channels read beside the record (a scheduling channel): searched, repaired and cut alike.
    despike_outliers : bool
    exclude : sequence of TimeWindow
    keep : array_like of bool (N,), optional
        The samples a model can use (a moving car's); the others are counted under ``left_out_as``.
    left_out_as : str
        The key under which ``left_out`` counts the samples outside ``keep``.
    min_run_samples : int
    holdout : float, optional
        Fraction of the kept samples, at the end, held out for validation.

    Raises
    ------
    InputError
        No run long enough to use, or a hold-out that leaves too few samples on one side.
    """
    extra = {name: np.asarray(values, dtype=float) for name, values in (extra or {}).items()}
    outliers = find_outliers(record, extra)
    n_u = record.n_u
    joined = record.replace(u=np.column_stack([record.u, *extra.values()]) if extra else record.u,
                            input_names=record.input_names + tuple(extra),
                            input_units=record.input_units + ("-",) * len(extra))
    if despike_outliers and outliers:
        joined = despike(joined, outliers)
    excluded, windows = exclusion_mask(record, exclude)
    usable = np.ones(record.n_samples, dtype=bool) if keep is None else np.asarray(keep, dtype=bool).ravel()
    if usable.shape != (record.n_samples,):
        raise InputError(f"the mask has {usable.size} samples; the record has {record.n_samples}")
    kept = excluded & usable
    source = str(record.meta.get("source", "record"))
    if not kept.any():
        raise InputError(f"{source}: no sample is left to identify from "
                         f"({_left_out_text(excluded, usable, left_out_as)})")
    cut = record.n_samples
    if holdout is not None:
        if not (isinstance(holdout, (int, float)) and 0.0 < holdout < 1.0):
            raise InputError(f"the validation fraction must lie strictly between 0 and 1; got {holdout!r}")
        places = np.flatnonzero(kept)
        kept_before = int(round((1.0 - holdout) * places.size))  # as IOData.split rounds
        if min(kept_before, places.size - kept_before) < 10:
            raise InputError(f"holding out {holdout:g} of the {places.size} samples used leaves too few on one side")
        cut = int(places[kept_before])
    parts: list[list[tuple[int, int]]] = [[], []]
    dropped = in_dropped = 0
    # the least length is for runs a cut made: a record kept whole is judged by what identifies from it
    shortest = max(int(min_run_samples), 2) if not kept.all() else 2
    used = np.zeros(record.n_samples, dtype=bool)
    for start, stop in _runs(kept):
        for side, (low, high) in enumerate(((start, min(stop, cut)), (max(start, cut), stop))):
            if high <= low:
                continue
            if high - low < shortest:
                dropped, in_dropped = dropped + 1, in_dropped + high - low
                continue
            parts[side].append((low, high))
            used[low:high] = True
    if not parts[0]:
        raise InputError(f"{source}: no run of at least {min_run_samples} samples is left to identify from "
                         f"({_left_out_text(excluded, usable, left_out_as)}; {dropped} shorter runs)")
    if holdout is not None and not parts[1]:
        raise InputError(f"{source}: the held-out part holds no run of at least {min_run_samples} samples")
    report: dict[str, Any] = {
        "source": source,
        "time_offset": float(record.meta.get("time_base", {}).get("time_offset", 0.0) or 0.0),
        "samples": record.n_samples,
        "outliers": [{**outlier.as_dict(), "treatment": "left out" if not used[outlier.index] else (
            "interpolated" if despike_outliers else "in the fit")} for outlier in outliers],
        "despiked": sum(1 for outlier in outliers if used[outlier.index]) if despike_outliers else None,
        "excluded": windows,
        "left_out": {"samples": int(record.n_samples - np.count_nonzero(used)),
                     "excluded": int(np.count_nonzero(~excluded)),
                     **({} if keep is None else {left_out_as: int(np.count_nonzero(excluded & ~usable))}),
                     "in_short_runs": int(in_dropped), "runs_dropped": int(dropped),
                     "min_run_samples": int(min_run_samples)},
        "runs": len(parts[0]) + len(parts[1]),  # estimation and held-out runs
    }

    def piece(low: int, high: int) -> tuple[IOData, dict[str, np.ndarray]]:
        part = joined[low:high]
        meta = {**dict(part.meta), "run": {"first_sample": low, "last_sample": high - 1}, "cleaning": report}
        channels = {name: part.u[:, n_u + i].copy() for i, name in enumerate(extra)}
        return part.replace(u=part.u[:, :n_u], input_names=record.input_names, input_units=record.input_units,
                            meta=meta), channels

    estimation = [piece(low, high) for low, high in parts[0]]
    validation = [piece(low, high) for low, high in parts[1]]
    follows = tuple(sum(1 for low, _ in parts[0] if low < start) - 1 for start, _ in parts[1])
    return CleanedRecord(
        tuple(p for p, _ in estimation), tuple(p for p, _ in validation), follows,
        {name: tuple(c[name] for _, c in estimation) for name in extra},
        {name: tuple(c[name] for _, c in validation) for name in extra}, report)


@dataclass(frozen=True, eq=False)
class CleanedRecords:
    """The runs of several records (:func:`clean_records`), in order.

    ``validation_follows`` gives, for each validation run, the index of the estimation run it
    continues (whose offsets prepare it); ``extra_estimation`` and ``extra_validation`` the extra
    channels of the runs, by name.
    """

    estimation: tuple[IOData, ...]
    validation: tuple[IOData, ...]
    validation_follows: tuple[int, ...]
    extra_estimation: dict[str, tuple[np.ndarray, ...]]
    extra_validation: dict[str, tuple[np.ndarray, ...]]


def clean_records(records: Sequence[IOData], *, extras: Sequence[Mapping[str, Any]] | None = None,
                  keeps: Sequence[Any] | None = None, min_run_samples: Sequence[int] | int = MIN_RUN_SAMPLES,
                  **options: Any) -> CleanedRecords:
    """:func:`clean_record` of each record (``extras``, ``keeps`` and ``min_run_samples`` per record; the
    other keywords alike for all), the runs of all records in order."""
    estimation: list[IOData] = []
    validation: list[IOData] = []
    follows: list[int] = []
    extra: tuple[dict[str, list[np.ndarray]], dict[str, list[np.ndarray]]] = ({}, {})
    for index, record in enumerate(records):
        shortest = min_run_samples if isinstance(min_run_samples, int) else min_run_samples[index]
        cleaned = clean_record(record, extra=None if extras is None else extras[index],
                               keep=None if keeps is None else keeps[index], min_run_samples=shortest, **options)
        follows += [len(estimation) + k for k in cleaned.validation_follows]
        estimation += cleaned.estimation
        validation += cleaned.validation
        for side, parts in ((0, cleaned.extra_estimation), (1, cleaned.extra_validation)):
            for name, values in parts.items():
                extra[side].setdefault(name, []).extend(values)
    return CleanedRecords(tuple(estimation), tuple(validation), tuple(follows),
                          {name: tuple(values) for name, values in extra[0].items()},
                          {name: tuple(values) for name, values in extra[1].items()})


def _left_out_text(excluded: np.ndarray, usable: np.ndarray, left_out_as: str) -> str:
    return (f"{np.count_nonzero(~excluded)} samples in --exclude windows, "
            f"{np.count_nonzero(excluded & ~usable)} {left_out_as.replace('_', ' ')}")


def _reports(records: Sequence[IOData]) -> list[dict[str, Any]]:
    """The cleaning reports of the records' sources, each once."""
    seen: dict[str, dict[str, Any]] = {}
    for record in records:
        report = record.meta.get("cleaning")
        if report is not None:
            seen.setdefault(f"{report['source']}@{report['time_offset']}@{report['samples']}", report)
    return list(seen.values())


def cleaning_summary(records: Sequence[IOData]) -> dict[str, Any]:
    """The JSON keys of the records' cleaning (empty where none was done).

    ``outliers`` (every spike and drop-out found: ``source``, ``channel``, ``time`` in the file's own
    time base, ``value`` as read, ``departure_mads``, ``treatment``: ``in the fit``, ``interpolated`` or
    ``left out``); with ``--despike`` ``despiked`` (how many were replaced by interpolation); ``left_out``
    (samples left out, by cause, summed over the files; ``runs``: how many runs of the rest, estimation
    and held-out, are records of their own),
    and with ``--exclude`` ``excluded`` (each window and the samples it held, per file).
    """
    reports = _reports(records)
    if not reports:
        return {}
    summary: dict[str, Any] = {
        "outliers": [{"source": r["source"], **o} for r in reports for o in r["outliers"]],
    }
    if any(r["despiked"] is not None for r in reports):
        summary["despiked"] = sum(r["despiked"] or 0 for r in reports)
    left_out: dict[str, Any] = {}
    for report in reports:
        for key, value in report["left_out"].items():
            left_out[key] = max(left_out.get(key, 0), value) if key == "min_run_samples" else \
                left_out.get(key, 0) + value
    left_out["runs"] = sum(r["runs"] for r in reports)
    summary["left_out"] = left_out
    if any(r["excluded"] for r in reports):
        summary["excluded"] = [{"source": r["source"], **row} for r in reports for row in r["excluded"]]
    return summary


def cleaning_warnings(records: Sequence[IOData], *, listed: int = 5) -> list[str]:
    """One warning naming the spikes and drop-outs that entered the fit (the first ``listed``), if any."""
    found = [(r, o) for r in _reports(records) for o in r["outliers"] if o["treatment"] == "in the fit"]
    if not found:
        return []
    channels = sorted({o["channel"] for _, o in found})
    shown = ", ".join(f"{o['channel']} {o['value']:.4g} at {time_text(o['time'] - r['time_offset'], r['time_offset'])}"
                      f"{'' if len(_reports(records)) == 1 else ' of ' + r['source']}" for r, o in found[:listed])
    more = f" and {len(found) - listed} more" if len(found) > listed else ""
    plural = "s" if len(found) > 1 else ""
    return [f"{len(found)} spike{plural} or drop-out{plural} in {', '.join(channels)} entered the fit "
            f"(samples departing from the median of the {WINDOW} around them by over {THRESHOLD:g} scaled MADs): "
            f"{shown}{more}; "
            "--despike replaces them by interpolation, --exclude T0:T1 leaves a stretch out"]


def cleaning_notes(records: Sequence[IOData]) -> list[str]:
    """What the cleaning did, one note each: spikes interpolated, samples and runs left out."""
    summary = cleaning_summary(records)
    notes = []
    if summary.get("despiked"):
        notes.append(f"{summary['despiked']} spike(s) or drop-out(s) replaced by straight lines between their "
                     "neighbours (--despike); the JSON key outliers lists their values as read")
    left_out = summary.get("left_out", {})
    if left_out.get("samples"):
        causes = [f"{value} {key.replace('_', ' ')}" for key, value in left_out.items()
                  if key not in ("samples", "runs_dropped", "min_run_samples", "runs", "in_short_runs") and value]
        if left_out.get("runs_dropped"):
            causes.append(f"{left_out['in_short_runs']} in {left_out['runs_dropped']} run(s) shorter than "
                          f"{left_out['min_run_samples']} samples")
        notes.append(f"{left_out['samples']} samples left out ({'; '.join(causes)}); each of the {left_out['runs']} "
                     "run(s) of the rest is a record of its own")
    return notes
