"""From raw sample times to one uniform time base: segment, jitter, gaps, resampling, decimation.

Applied to a :class:`~identification.dataio.readers.RawRecord` in this order: ``segment`` (file time, or
from the log's first sample: :mod:`~vehid.identification.dataio.timewindow`); time
counted from the first sample; the checks that time increases with no gap (:data:`GAP_FACTOR`; with
``resample`` a gap is bridged and reported instead); sample times within ``jitter_tolerance`` of the
uniform grid put on it; ``resample`` (linear interpolation, a faster channel low-passed first);
``decimate``. The rules are in docs/measured_data.md ("Time base"); what was done goes into
``meta["time_base"]``.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from ..data import IOData
from ..choices import JITTER_TOLERANCE
from ..errors import InputError, OptionError
from .readers import RawRecord
from .timewindow import TimeWindow, edge_slack, parse_time_window, span_text, time_text

__all__ = ["JITTER_TOLERANCE", "GAP_FACTOR", "ANTI_ALIAS_CUTOFF", "uniform_record", "parse_segment"]

#: A step longer than this many median steps is a gap in the record.
GAP_FACTOR = 2.0
#: Cut-off of the anti-aliasing low-pass before resampling to a lower rate, as a fraction of the new Nyquist frequency.
ANTI_ALIAS_CUTOFF = 0.8
_ANTI_ALIAS_ORDER = 8
#: File time is kept as the record's time while it lies within this many steps of zero: its rounding then
#: moves a sample by less than 1e-9 of a step. Further out (epoch stamps, 1.7e9 s at 0.02 s steps, carry
#: only 2.4e-7 s of resolution) time counts from the first sample and ``time_offset`` says where that was.
FILE_TIME_STEPS = 1e6
#: Source and target rates within this fraction of each other count as one rate when resampling: jittered
#: stamps put the median step a few 1e-7 off the nominal one, and folding the top 0.1 % of the band is nothing
#: an anti-aliasing filter is needed for.
_SAME_RATE = 1e-3
#: Gaps bridged by resampling that are listed one by one (all are counted).
_GAPS_LISTED = 20


def parse_segment(text: str | Sequence[float] | TimeWindow | None) -> TimeWindow | None:
    """A segment (``"T0:T1"`` file time, ``"+T0:+T1"`` from the log's first sample, a pair, a window):
    :func:`~vehid.identification.dataio.timewindow.parse_time_window`."""
    return parse_time_window(text, option="segment")


def _record_time_is_file_time(times: Sequence[np.ndarray]) -> bool:
    """Whether the record will keep the file's own time (:data:`FILE_TIME_STEPS`), judged from the raw times."""
    first = times[0]
    if first.size < 2:
        return True
    step = float(np.median(np.diff(first)))
    span = max(abs(float(t[0])) for t in times) + max(float(t[-1] - t[0]) for t in times)
    return step > 0 and span <= FILE_TIME_STEPS * step


def _row(rows: np.ndarray | None, k: int) -> int:
    return k if rows is None else int(rows[k])


def _check_increasing(raw: RawRecord, channel: int, t: np.ndarray, rows: np.ndarray | None, offset: float,
                      bridge_gaps: bool, file_time: bool = True) -> tuple[float, list[dict[str, Any]], int]:
    """The median step of ``t`` (counted from ``offset``), after checking that time increases.

    A gap (a step longer than :data:`GAP_FACTOR` median steps) is an error, unless ``bridge_gaps``
    (resampling interpolates across it): then the gaps are returned, the first :data:`_GAPS_LISTED` of
    them described, with their total count. Messages give times as the record will (``file_time``:
    the file's own, else from its first sample).
    """

    def shown(value: float) -> str:
        return time_text(value + offset) if file_time else time_text(value, offset)

    if t.size < 2:
        raise InputError(f"{raw.source}: {raw.names[channel]!r} has fewer than 2 samples")
    steps = np.diff(t)
    falling = np.flatnonzero(~(steps > 0))
    if falling.size:
        k = int(falling[0])
        raise InputError(
            f"{raw.source}: time does not increase at {raw.locate(channel, _row(rows, k + 1))} "
            f"({shown(t[k + 1])} after {shown(t[k])})"
        )
    median = float(np.median(steps))
    gaps = np.flatnonzero(steps > GAP_FACTOR * median)
    if gaps.size and not bridge_gaps:
        k = int(gaps[0])
        raise OptionError(
            f"{raw.source}: gap in time at {raw.locate(channel, _row(rows, k + 1))}: {steps[k]:.6g} s after the "
            f"previous sample, {steps[k] / median:.1f} times the median step of {median:.6g} s; 'resample' HZ "
            "interpolates across it, 'segment' T0:T1 leaves it out", "resample", "segment"
        )
    described = [{"channel": raw.names[channel], "at_s": float(t[k + 1] + offset), "length_s": float(steps[k]),
                  "steps": float(steps[k] / median), "location": raw.locate(channel, _row(rows, k + 1))}
                 for k in gaps[:_GAPS_LISTED]]
    return median, described, int(gaps.size)


def _merge_repeated_stamps(t: np.ndarray, values: np.ndarray, rows: np.ndarray | None
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, int]:
    """Samples that share a time stamp as one sample, their mean; how many were merged away.

    Falling time is left for :func:`_check_increasing` to name; only runs of equal stamps are merged.
    """
    same = np.diff(t) == 0
    if not same.any():
        return t, values, rows, 0
    first = np.concatenate([[True], ~same])
    group = np.cumsum(first) - 1
    mean = np.bincount(group, weights=values) / np.bincount(group)
    places = np.flatnonzero(first)
    return t[first], mean, places if rows is None else rows[places], int(same.sum())


def _stray(t: np.ndarray) -> np.ndarray:
    """Distance of each sample time from the uniform grid through the first and last, in steps."""
    step = (t[-1] - t[0]) / (t.size - 1)
    return np.abs(t - (t[0] + np.arange(t.size) * step)) / step


def _low_pass_onto(t: np.ndarray, values: np.ndarray, source_step: float, grid: np.ndarray, rate: float,
                   raw: RawRecord, channel: int) -> np.ndarray:
    """Anti-aliased resampling of one channel onto a grid of a lower rate."""
    import scipy.signal  # a second to import: paid on first use

    count = int(math.floor((t[-1] - t[0]) / source_step + 1e-9)) + 1
    fine_t = t[0] + np.arange(count) * source_step
    fine = np.interp(fine_t, t, values)
    sos = scipy.signal.butter(_ANTI_ALIAS_ORDER, ANTI_ALIAS_CUTOFF * rate / 2, fs=1.0 / source_step, output="sos")
    pad = 3 * (2 * len(sos) + 1)
    if fine.size <= pad:
        raise InputError(f"{raw.source}: {raw.names[channel]!r} has too few samples ({fine.size}) to filter "
                         f"before resampling")
    return np.interp(grid, fine_t, scipy.signal.sosfiltfilt(sos, fine))


def _columns_of_one_table(columns: list[np.ndarray]) -> np.ndarray:
    """The columns as one (N, k) array: a view where they are the first k columns of one parsed table, else a stack."""
    base = columns[0].base
    if base is not None and base.ndim == 2 and base.shape[0] == columns[0].size and base.dtype == np.float64:
        origin = base.__array_interface__["data"][0]
        if all(c.base is base and c.strides == (base.strides[0],)
               and c.__array_interface__["data"][0] == origin + i * base.strides[1] for i, c in enumerate(columns)):
            return base[:, : len(columns)]
    return np.column_stack(columns)


def uniform_record(
    raw: RawRecord,
    *,
    n_inputs: int,
    dt: float | None = None,
    resample: float | None = None,
    decimate: int | None = None,
    segment: tuple[float, float] | str | None = None,
    jitter_tolerance: float = JITTER_TOLERANCE,
    meta: dict[str, Any] | None = None,
) -> IOData:
    """Make a uniformly sampled record of a raw one (steps in the module docstring).

    Parameters
    ----------
    raw : RawRecord
        Inputs first (``n_inputs`` channels), then outputs.
    n_inputs : int
        How many of its channels are inputs.
    dt : float, optional
        Sample interval where the record has no time.
    resample : float, optional
        Rate in Hz of the uniform grid to interpolate onto.
    decimate : int, optional
        Keep every K-th sample after anti-aliasing.
    segment : TimeWindow, (T0, T1), "T0:T1" or "+T0:+T1", optional
        Only the samples in this window (:func:`~vehid.identification.dataio.timewindow.parse_time_window`).
    jitter_tolerance : float
        See :data:`JITTER_TOLERANCE`.
    meta : dict, optional
        Added to the record's metadata.

    Returns
    -------
    IOData
        The record; ``meta["time_base"]`` says what was done to the time (jitter, resampling, segment).

    Raises
    ------
    InputError
        Time not increasing, a gap, jitter beyond the tolerance, an empty
        segment, a bad rate or factor.
    """
    if not (math.isfinite(jitter_tolerance) and 0 <= jitter_tolerance < 0.5):
        raise InputError(f"the jitter tolerance is a fraction of a step in [0, 0.5); got {jitter_tolerance!r}")
    if resample is not None and not (math.isfinite(resample) and resample > 0):
        raise InputError(f"the resampling rate must be a positive number of Hz; got {resample!r}")
    if decimate is not None and (isinstance(decimate, bool) or int(decimate) != decimate or decimate < 1):
        raise InputError(f"the decimation factor must be a whole number >= 1; got {decimate!r}")
    segment = parse_segment(segment)
    times = list(raw.times)
    if times[0] is None:
        if dt is None:
            raise InputError(f"{raw.source} has no time: give dt")
        times = [np.arange(raw.values[0].size) * float(dt)] * len(times)
    values = list(raw.values)
    rows: list[np.ndarray | None] = [None] * len(values)  # file rows of the samples, where a segment selected them
    file_time = _record_time_is_file_time(times)
    first_sample = min(float(t[0]) for t in times)  # the log's first sample: where "+T0" counts from
    if segment is not None:
        low, high = segment.in_file_time(first_sample)
        for c, t in enumerate(times):
            slack = edge_slack(float(t[-1]), float(t[1] - t[0]) if t.size > 1 else 0.0)
            keep = np.flatnonzero((t >= low - slack) & (t <= high + slack))
            if keep.size < 2:
                span = span_text(float(t[0]), float(t[-1])) if file_time else span_text(
                    float(t[0]) - first_sample, float(t[-1]) - first_sample, first_sample)
                hint = "" if segment.from_start or file_time else (
                    ": a segment without + is in the file's time; +T0:+T1 counts from the log's first sample")
                raise InputError(f"the segment {segment} s selects {keep.size} samples of {raw.names[c]!r} in "
                                 f"{raw.source}, which {span}{hint}")
            times[c], values[c], rows[c] = t[keep], values[c][keep], keep
    # time from the first sample, before any check: epoch stamps keep their resolution in the differences
    offset = min(float(t[0]) for t in times)
    times = [t - offset for t in times]
    shared = raw.shares_time
    repeated = 0
    if resample is not None:  # loggers stamp coarsely: samples sharing a stamp become their mean there
        for c in range(len(times)):
            times[c], values[c], rows[c], merged = _merge_repeated_stamps(times[c], values[c], rows[c])
            repeated = max(repeated, merged)
    checked = [_check_increasing(raw, c, times[c], rows[c], offset, bridge_gaps=resample is not None,
                                 file_time=file_time)
               for c in (range(1) if shared else range(len(times)))]
    steps = [median for median, _, _ in checked]
    strays = [_stray(t) for t in (times[:1] if shared else times)]
    jitter = max(float(np.max(stray)) for stray in strays)
    report: dict[str, Any] = {"sample_jitter": jitter, "resample": None, "decimate": None, "log_start": first_sample,
                              "segment": None if segment is None else list(segment.in_file_time(first_sample))}
    if repeated:
        report["repeated_stamps"] = repeated
    gap_count = sum(count for _, _, count in checked)
    if gap_count:
        report["gaps"] = [gap for _, described, _ in checked for gap in described][:_GAPS_LISTED]
        report["gap_count"] = gap_count
    if resample is None and shared:
        stray = strays[0]
        if jitter > jitter_tolerance:
            k = int(np.flatnonzero(stray > jitter_tolerance)[0])
            raise OptionError(
                f"{raw.source}: sample times stray from a uniform grid by {stray[k]:.3g} of a step at "
                f"{raw.locate(0, _row(rows[0], k))} (tolerance {jitter_tolerance:g}): resample with "
                f"'resample' HZ, or widen 'jitter_tolerance'", "resample", "jitter_tolerance"
            )
        count = times[0].size
        t = np.arange(count) * (times[0][-1] / (count - 1))
        columns = values
    else:
        rate = float(resample) if resample is not None else 1.0 / min(steps)
        start = max(float(t[0]) for t in times)
        stop = min(float(t[-1]) for t in times)
        count = int(math.floor((stop - start) * rate + 1e-9)) + 1
        if count < 2:
            raise InputError(f"{raw.source}: the chosen channels share less than two samples at {rate:g} Hz")
        t = start + np.arange(count) / rate
        columns, filtered = [], []
        for c, (tc, vc) in enumerate(zip(times, values)):
            source_step = steps[0] if shared else steps[c]
            if rate * source_step < 1.0 - _SAME_RATE:
                columns.append(_low_pass_onto(tc, vc, source_step, t, rate, raw, c))
                filtered.append(raw.names[c])
            else:
                columns.append(np.interp(t, tc, vc))
        report["resample"] = {
            "rate_hz": rate,
            "interpolation": "linear",
            "anti_aliasing": (f"{_ANTI_ALIAS_ORDER}th-order Butterworth low-pass at {ANTI_ALIAS_CUTOFF:g} of the "
                              "new Nyquist frequency, zero phase") if filtered else None,
            "filtered_channels": filtered,
        }
    step = float(t[1] - t[0])
    if abs(offset) + float(t[-1]) <= FILE_TIME_STEPS * step:
        t, offset = t + offset, 0.0  # near zero the file's own time is kept, exactly enough
    report["time_offset"] = offset
    del strays
    table = _columns_of_one_table(columns)
    if decimate is not None and decimate > 1:
        factor = int(decimate)
        if table.shape[0] < 2 * factor:
            raise InputError(f"{raw.source}: {table.shape[0]} samples are too few to decimate by {factor}")
        import scipy.signal  # imported here for the reason given in _low_pass_onto

        # decimate pads with zeros, which pulls a channel far from zero (a speed) towards it near both
        # ends; an odd reflection about the end samples, a whole number of factors long, keeps the ends
        # and the sample alignment
        pad = factor * min(20, (table.shape[0] - 1) // factor)
        padded = np.concatenate([2 * table[:1] - table[pad:0:-1], table,
                                 2 * table[-1:] - table[-2:-pad - 2:-1]], axis=0)
        kept = -(-table.shape[0] // factor)
        table = scipy.signal.decimate(padded, factor, ftype="fir", axis=0, zero_phase=True)[
            pad // factor:pad // factor + kept]
        t = t[::factor]
        report["decimate"] = {"factor": factor, "filter": f"FIR, Hamming window, order {20 * factor}, zero phase"}
    names, units = raw.names, raw.units
    return IOData(
        t=t,
        u=table[:, :n_inputs],
        y=table[:, n_inputs:],
        input_names=names[:n_inputs],
        output_names=names[n_inputs:],
        input_units=units[:n_inputs],
        output_units=units[n_inputs:],
        meta={"source": raw.source, "time_base": report, **(meta or {})},
    )
