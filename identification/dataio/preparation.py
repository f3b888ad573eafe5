"""Reading settings and data preparation, kept with the model so that it can be applied to raw files again.

A model identified from measured data is a model of prepared signals: each channel multiplied by its
scale factor, then its offset removed, per estimation record (runs of a campaign sit at different
operating points); the sample-weighted mean of the offsets is the model's operating point for any
other data. A :class:`Preparation` (frozen) holds the :class:`ReadSettings`, the factors and the offsets
and is archived with a run, so that ``prepare_validation(path, preparation)`` re-applies it.
docs/measured_data.md ("Preparation") shows the workflow.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..data import IOData, as_records, check_channels, read_hdf5
from ..choices import DETREND, DETRENDS, HDF5_SUFFIXES
from ..errors import InputError, OptionError
from ..optionspec import check_value
from .readers import RawRecord, expand_channels, read_raw
from .timebase import JITTER_TOLERANCE, parse_segment, uniform_record
from .timewindow import TimeWindow

__all__ = [
    "DETRENDS",
    "TIME_UNITS",
    "ReadSettings",
    "RecordOffsets",
    "Preparation",
    "read_record",
    "estimate_preparation",
    "prepare",
    "load_records",
    "read_raw_records",
    "prepare_validation",
    "parse_scale",
    "parse_steering_ratio",
]


#: Seconds per unit, for the units a file may give its time column (its header ``t(ms)`` or units row).
TIME_UNITS = {"s": 1.0, "sec": 1.0, "secs": 1.0, "second": 1.0, "seconds": 1.0, "ms": 1e-3, "msec": 1e-3,
              "us": 1e-6, "µs": 1e-6, "μs": 1e-6, "usec": 1e-6, "ns": 1e-9, "min": 60.0, "h": 3600.0}


@dataclass(frozen=True)
class ReadSettings:
    """How a record is read from a file and put on a uniform time base (the CLI's options of the same names).

    Attributes
    ----------
    inputs, outputs : tuple of str
        Channel names (or 1-based column numbers of text tables); empty for
        a workbench HDF5 record means all of its inputs or outputs.
    time_column : str or None
        Time column or variable; None: ``t`` when present; ``"none"``: no time column.
    dt : float or None
        Sample interval in s, where there is no time column.
    resample : float or None
        Rate in Hz of a uniform grid to interpolate onto.
    decimate : int or None
        Keep every K-th sample after an anti-aliasing filter.
    segment : (float, float) or None
        Only ``T0 <= t <= T1`` (s): file time, or from the log's first sample where
        ``segment_from_start``. Given as text, ``"T0:T1"`` or ``"+T0:+T1"``
        (:func:`~vehid.identification.dataio.timewindow.parse_time_window`), it sets both fields.
    jitter_tolerance : float
        Largest stray of a sample time from the uniform grid, as a fraction of a step.
    time_scale : float or None
        Seconds per unit of the time column (0.001 for milliseconds); None:
        from the unit the file gives the column (:data:`TIME_UNITS`), else 1.
    segment_from_start : bool
        The segment counts from the log's first sample (``+T0:+T1``).
    """

    inputs: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()
    time_column: str | None = None
    dt: float | None = None
    resample: float | None = None
    decimate: int | None = None
    segment: tuple[float, float] | None = None
    jitter_tolerance: float = JITTER_TOLERANCE
    time_scale: float | None = None
    segment_from_start: bool = False

    @property
    def window(self) -> TimeWindow | None:
        """The segment as a :class:`~vehid.identification.dataio.timewindow.TimeWindow` (None: the whole file)."""
        return None if self.segment is None else TimeWindow(*self.segment, self.segment_from_start)

    def __post_init__(self) -> None:
        object.__setattr__(self, "inputs", tuple(str(n).strip() for n in self.inputs))
        object.__setattr__(self, "outputs", tuple(str(n).strip() for n in self.outputs))
        window = parse_segment(self.segment)
        if window is not None and not isinstance(self.segment, (tuple, list)):  # text or a window: says which time
            object.__setattr__(self, "segment_from_start", window.from_start)
        object.__setattr__(self, "segment", None if window is None else (window.start, window.stop))
        if window is None:
            object.__setattr__(self, "segment_from_start", False)
        for kind, names in (("input", self.inputs), ("output", self.outputs)):
            if any(not name for name in names):
                raise InputError(f"an empty {kind} column name was given")
        both = [n for n in self.inputs if n in self.outputs]
        if both:
            raise InputError(f"column {both[0]!r} is named both as an input and as an output")
        if self.time_scale is not None:
            if not (isinstance(self.time_scale, (int, float)) and math.isfinite(self.time_scale)
                    and self.time_scale > 0):
                raise InputError(f"the time scale is a positive number of seconds per unit of the time column; "
                                 f"got {self.time_scale!r}")
            if self.dt is not None:
                raise OptionError("'time_scale' converts a time column; 'dt' is already in seconds", "time_scale", "dt")


def read_record(path: str | Path, settings: ReadSettings | None = None, **options: Any) -> IOData:
    """Read one raw record, uniformly sampled, in the file's units (no offsets removed, no scaling).

    Parameters
    ----------
    path : str or Path
        ``.csv``, ``.dat``, ``.txt``, ``.mat``, ``.mf4`` or a workbench ``.h5`` file.
    settings : ReadSettings, optional
        How to read it: channels, time base, resampling, segment.
    **options
        Or the fields of :class:`ReadSettings` as keywords: ``inputs``,
        ``outputs``, ``time_column``, ``dt``, ``resample``, ``decimate``,
        ``segment``, ``jitter_tolerance``.

    Returns
    -------
    IOData
        With ``meta["source"]`` and ``meta["time_base"]`` (``sample_jitter``,
        and what resampling, decimation and segment were applied).

    Examples
    --------
    A table logged in milliseconds, read with its time in seconds and only its second half kept:

    >>> import pathlib, tempfile
    >>> from vehid.identification import read_record
    >>> rows = "".join(f"{10 * k},{0.1 * (k > 1):.1f},{0.02 * k:.2f}\\n" for k in range(6))
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = pathlib.Path(folder) / "step.csv"
    ...     _ = path.write_text("time(ms),steer,yaw_rate\\n" + rows)
    ...     record = read_record(path, inputs=("steer",), outputs=("yaw_rate",), segment="+0.025:+0.05")
    >>> round(record.dt, 9), record.t, record.output("yaw_rate")
    (0.01, array([0.03, 0.04, 0.05]), array([0.06, 0.08, 0.1 ]))
    """
    if settings is None:
        settings = ReadSettings(**options)
    elif options:
        settings = replace(settings, **options)
    path = Path(path)
    if path.suffix.lower() in HDF5_SUFFIXES:
        data = _hdf5_record(path, settings)
        raw, n_inputs = _as_raw(data), data.n_u
    else:
        if not settings.inputs or not settings.outputs:
            raise OptionError(f"{path.name} needs 'inputs' and 'outputs' naming its columns", "inputs", "outputs")
        # a MATLAB matrix named without a column stands for all of its columns
        inputs, outputs = expand_channels(path, settings.inputs), expand_channels(path, settings.outputs)
        raw = read_raw(path, channels=inputs + outputs, time_column=settings.time_column, dt=settings.dt)
        n_inputs = len(inputs)
    raw, time_scale = _time_in_seconds(raw, settings.time_scale)
    data = uniform_record(raw, n_inputs=n_inputs, dt=settings.dt, resample=settings.resample,
                          decimate=settings.decimate, segment=settings.window,
                          jitter_tolerance=settings.jitter_tolerance)
    data.meta["time_base"]["time_scale"] = time_scale
    return data


def _time_in_seconds(raw: RawRecord, time_scale: float | None) -> tuple[RawRecord, float]:
    """The record with its time in seconds: times ``time_scale``, or as the file's unit for the column says."""
    if raw.times[0] is None:
        return raw, 1.0
    if time_scale is None:
        time_scale = TIME_UNITS.get((raw.time_unit or "").strip(), 1.0)
    if time_scale == 1.0:
        return raw, 1.0
    scaled: dict[int, np.ndarray] = {}  # channels sharing one array of times keep sharing one
    times = tuple(scaled.setdefault(id(t), t * time_scale) for t in raw.times)
    return replace(raw, times=times), float(time_scale)


def _hdf5_record(path: Path, settings: ReadSettings) -> IOData:
    if settings.dt is not None or settings.time_scale is not None:
        option = "dt" if settings.dt is not None else "time_scale"
        raise OptionError(f"'{option}' applies to files' time columns; an HDF5 record carries its own time base", option)
    data = read_hdf5(path)
    if settings.inputs:
        data = data.select_inputs(settings.inputs)
    if settings.outputs:
        data = data.select_outputs(settings.outputs)
    return data


def _as_raw(data: IOData) -> RawRecord:
    values = tuple(np.ascontiguousarray(c) for c in (*data.u.T, *data.y.T))
    return RawRecord(str(data.meta.get("source", "record")), data.input_names + data.output_names, values,
                     (data.t,) * len(values), data.input_units + data.output_units, "t")


@dataclass(frozen=True, eq=False)
class RecordOffsets:
    """The offsets removed from one estimation record (in scaled units).

    The offset of a channel at time ``t`` is ``offset + slope (t - t_start)``,
    ``t_start`` the record's first sample time; the slope is zero unless
    ``detrend="linear"``.

    Attributes
    ----------
    source : str
        The record's source (its file, or ``"record"``).
    samples : int
        Its number of samples (the weight of its offsets in the model's operating point).
    input_offset, output_offset : ndarray, shapes (n_u,) and (n_y,)
        The offsets at the record's start.
    input_slope, output_slope : ndarray, shapes (n_u,) and (n_y,)
        Their slopes (units per second).
    """

    source: str
    samples: int
    input_offset: np.ndarray
    output_offset: np.ndarray
    input_slope: np.ndarray
    output_slope: np.ndarray


def _named_numbers(items: Any, what: str, form: str) -> list[tuple[str | None, str]]:
    """``NAME=NUMBER`` items (strings, each possibly a comma-separated list) as (name, text) pairs.

    A bare number, allowed only where ``form`` says so, comes back with the name None.
    """
    pairs: list[tuple[str | None, str]] = []
    for item in [items] if isinstance(items, (str, int, float)) else items:
        if isinstance(item, (int, float)) and not isinstance(item, bool):
            pairs.append((None, repr(float(item))))
            continue
        for part in str(item).split(","):
            name, equals, number = part.rpartition("=")
            if not part.strip() or (equals and not name.strip()):
                raise InputError(f"{what} is {form}; got {str(item)!r}")
            pairs.append((name.strip() if equals else None, number.strip()))
    return pairs


def _number(text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{what} is not a number: {text!r}") from None
    return value


def parse_scale(items: Mapping[str, float] | Sequence[str] | str | None) -> dict[str, float]:
    """Scale factors from a mapping or from ``NAME=FACTOR`` strings (the CLI's ``--scale``).

    Each string may list several, ``"yawRate=0.0174533,ayCG=-1"``; a negative
    factor turns a channel whose axis points the other way.
    """
    if items is None:
        return {}
    if isinstance(items, Mapping):
        pairs = list(items.items())
    else:
        pairs = []
        for name, factor in _named_numbers(items, "a scale", "NAME=FACTOR"):
            if name is None:
                raise InputError(f"a scale is NAME=FACTOR; got {factor!r}")
            pairs.append((name, _number(factor, f"the scale factor of {name!r}")))
    scale: dict[str, float] = {}
    for name, factor in pairs:
        if not (isinstance(factor, (int, float)) and math.isfinite(factor) and factor != 0):
            raise InputError(f"the scale factor of {name!r} must be a finite non-zero number; got {factor!r}")
        if name in scale:
            raise InputError(f"channel {name!r} is scaled twice")
        scale[str(name)] = float(factor)
    return scale


def parse_steering_ratio(items: Mapping[str, float] | Sequence[str] | str | float | None,
                         inputs: Sequence[str]) -> dict[str, float]:
    """Steering ratios: ``RATIO`` for the only input, or ``NAME=RATIO`` (the CLI's ``--steering-ratio``).

    A steering-wheel angle divided by the ratio is the road-wheel angle; the
    ratio is positive (a flipped axis is a ``--scale`` of -1).
    """
    if items is None:
        return {}
    if isinstance(items, Mapping):
        pairs = [(str(name), value) for name, value in items.items()]
    else:
        pairs = []
        for name, ratio in _named_numbers(items, "a steering ratio", "RATIO or NAME=RATIO"):
            if name is None:
                if len(inputs) != 1:
                    raise OptionError(f"there are {len(inputs)} inputs ({', '.join(inputs)}): name the steering "
                                      f"channel as 'steering_ratio' NAME={ratio}", "steering_ratio")
                name = inputs[0]
            pairs.append((name, _number(ratio, f"the steering ratio of {name!r}")))
    ratios: dict[str, float] = {}
    for name, ratio in pairs:
        if not (isinstance(ratio, (int, float)) and math.isfinite(ratio) and ratio > 0):
            raise InputError(f"the steering ratio of {name!r} must be a finite positive number; got {ratio!r}")
        if name in ratios:
            raise InputError(f"channel {name!r} has two steering ratios")
        ratios[name] = float(ratio)
    return ratios


@dataclass(frozen=True, eq=False)
class Preparation:
    """Scale factors and offsets that turn raw records into the model's signals: a frozen value.

    ``prepared = scale * raw - offset(t)`` per channel. Build one with
    :func:`estimate_preparation` (or :func:`prepare`, :func:`load_records`);
    apply it with :meth:`apply` or :func:`prepare_validation`.

    Attributes
    ----------
    input_names, output_names : tuple of str
        The channels, as the raw records name them.
    input_scale, output_scale : ndarray
        Factors multiplying the raw channels.
    detrend : {"mean", "linear", "none"}
        What was removed from each record: its mean, a straight line, or nothing.
    offsets : tuple of RecordOffsets
        One per estimation record, in order.
    settings : ReadSettings or None
        How the estimation records were read (None for records given in memory).
    conversions : dict
        What each factor is made of, per converted channel: ``{"scale": f}``
        (a unit or sign, ``--scale``) and ``{"steering_ratio": r}`` (the
        factor divides by it); the factor is their product. Empty when no
        channel is converted.
    """

    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    input_scale: np.ndarray
    output_scale: np.ndarray
    detrend: str
    offsets: tuple[RecordOffsets, ...]
    settings: ReadSettings | None = None
    conversions: dict[str, dict[str, float]] = field(default_factory=dict)

    def _pooled(self, name: str) -> np.ndarray:
        weights = np.array([o.samples for o in self.offsets], dtype=float)
        return np.average(np.array([getattr(o, name) for o in self.offsets]), axis=0, weights=weights)

    @property
    def input_offset(self) -> np.ndarray:
        """The model's input operating point: the sample-weighted mean of the records' offsets."""
        return self._pooled("input_offset")

    @property
    def output_offset(self) -> np.ndarray:
        """The model's output operating point (as :attr:`input_offset`)."""
        return self._pooled("output_offset")

    def _offsets(self, record: int | None) -> RecordOffsets:
        if record is None:
            return RecordOffsets("model", 0, self.input_offset, self.output_offset,
                                 self._pooled("input_slope"), self._pooled("output_slope"))
        if not 0 <= record < len(self.offsets):
            raise InputError(f"the preparation holds {len(self.offsets)} records; no record {record}")
        return self.offsets[record]

    def _check(self, data: IOData) -> None:
        if data.input_names != self.input_names or data.output_names != self.output_names:
            raise InputError(
                f"the record's channels ({', '.join(data.input_names)} -> {', '.join(data.output_names)}) "
                f"differ from the model's ({', '.join(self.input_names)} -> {', '.join(self.output_names)})"
            )

    def apply(self, data: IOData, record: int | None = None) -> IOData:
        """The prepared record: scaled, offsets removed.

        Parameters
        ----------
        data : IOData
            A raw record with the model's channels.
        record : int, optional
            Use the offsets of estimation record ``record``; by default the
            model's operating point (:attr:`input_offset`, :attr:`output_offset`).

        Returns
        -------
        IOData
            The prepared record (``meta["preparation"]`` says which offsets).
        """
        self._check(data)
        offsets = self._offsets(record)
        elapsed = (data.t - data.t[0])[:, None]
        u = data.u * self.input_scale - offsets.input_offset - elapsed * offsets.input_slope
        y = data.y * self.output_scale - offsets.output_offset - elapsed * offsets.output_slope
        meta = dict(data.meta)
        meta["preparation"] = {"detrend": self.detrend, "offsets_of": offsets.source}
        return data.replace(u=u, y=y, meta=meta)

    def restore_outputs(self, y: np.ndarray, t: np.ndarray, record: int | None = None) -> np.ndarray:
        """Restore outputs of the model (prepared units) to the raw file's units and offsets.

        Parameters
        ----------
        y : ndarray, shape (N, n_y)
            Outputs in prepared units.
        t : ndarray, shape (N,)
            Their times (s): a linear trend is restored from the first.
        record : int, optional
            Restore the offsets of estimation record ``record``; the model's by default.

        Returns
        -------
        ndarray, shape (N, n_y)
            The outputs in raw units.
        """
        offsets = self._offsets(record)
        elapsed = (np.asarray(t) - t[0])[:, None]
        return (np.asarray(y) + offsets.output_offset + elapsed * offsets.output_slope) / self.output_scale

    def simulate(self, model: Any, data: IOData, record: int | None = None) -> np.ndarray:
        """Simulate a model on a raw record, in raw units: prepare the inputs, simulate from rest, restore.

        Parameters
        ----------
        model : IdentifiedModel
            A model identified on records this preparation prepared.
        data : IOData
            A raw record with the model's channels.
        record : int, optional
            Use the offsets of estimation record ``record``; the model's by default.

        Returns
        -------
        ndarray, shape (N, n_y)
            The model's outputs in the raw file's units.
        """
        prepared = self.apply(data, record)
        return self.restore_outputs(model.simulate_outputs(prepared.u, prepared.dt), data.t, record)

    def conversion_list(self) -> list[dict[str, Any]]:
        """List the converted channels.

        Returns
        -------
        list of dict
            Per converted channel: ``channel``, ``factor`` (multiplying the raw channel)
            and what the factor is made of (``scale``, ``steering_ratio``).
        """
        factors = dict(zip(self.input_names + self.output_names,
                           (*map(float, self.input_scale), *map(float, self.output_scale))))
        return [{"channel": name, "factor": factors.get(name, 1.0), **parts}
                for name, parts in self.conversions.items()]

    def as_dict(self) -> dict[str, Any]:
        """Describe the preparation for JSON (saved beside a model).

        Returns
        -------
        dict
            Channels, scales, detrend, the offsets per record, the reading settings and the conversions.
        """
        return {
            "inputs": list(self.input_names),
            "outputs": list(self.output_names),
            "input_scale": self.input_scale.tolist(),
            "output_scale": self.output_scale.tolist(),
            "detrend": self.detrend,
            "input_offset": self.input_offset.tolist(),
            "output_offset": self.output_offset.tolist(),
            "records": [
                {"source": o.source, "samples": o.samples, "input_offset": o.input_offset.tolist(),
                 "output_offset": o.output_offset.tolist(), "input_slope": o.input_slope.tolist(),
                 "output_slope": o.output_slope.tolist()}
                for o in self.offsets
            ],
            "conversions": self.conversion_list(),
            "settings": None if self.settings is None else {
                k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(self.settings).items()
            },
        }


def _named_channels(name: str, channels: tuple[str, ...]) -> list[str]:
    """The channels a name stands for: itself, or every column ``name:k`` of a matrix variable."""
    if name in channels:
        return [name]
    return [channel for channel in channels if channel.rpartition(":")[0] == name]


def _conversions(first: IOData, scale: Mapping[str, float], steering_ratio: Mapping[str, float]
                 ) -> dict[str, dict[str, float]]:
    """Per channel, its scale and steering ratio; a name that is not a chosen channel is an error."""
    channels = first.input_names + first.output_names
    conversions: dict[str, dict[str, float]] = {}
    for option, values in (("scale", scale), ("steering_ratio", steering_ratio)):
        for name, value in values.items():
            named = _named_channels(name, channels)
            if not named:
                raise OptionError(
                    f"'{option}' names {name!r}, which is not a chosen channel; inputs: "
                    f"{', '.join(first.input_names)}; outputs: {', '.join(first.output_names)}", option
                )
            for channel in named:
                if option in conversions.setdefault(channel, {}):
                    raise OptionError(f"channel {channel!r} is given '{option}' twice (as {name!r})", option)
                conversions[channel][option] = value
    return {name: conversions[name] for name in channels if name in conversions}


def _factor(parts: Mapping[str, float]) -> float:
    return parts.get("scale", 1.0) / parts.get("steering_ratio", 1.0)


def _scale_factors(first: IOData, conversions: Mapping[str, Mapping[str, float]]) -> tuple[np.ndarray, np.ndarray]:
    """The factors of the record's inputs and outputs."""
    return tuple(np.array([_factor(conversions.get(name, {})) for name in names], dtype=float)
                 for names in (first.input_names, first.output_names))  # type: ignore[return-value]


def _trend(t: np.ndarray, values: np.ndarray, detrend: str) -> tuple[np.ndarray, np.ndarray]:
    """Offset at the record's start and slope per second of each column."""
    if detrend == "none":
        return np.zeros(values.shape[1]), np.zeros(values.shape[1])
    if detrend == "mean":
        return values.mean(axis=0), np.zeros(values.shape[1])
    slope, intercept = np.polyfit(t - t[0], values, 1)
    return intercept, slope


def estimate_preparation(
    records: IOData | Sequence[IOData],
    *,
    detrend: str = "mean",
    scale: Mapping[str, float] | Sequence[str] | None = None,
    settings: ReadSettings | None = None,
    steering_ratio: Mapping[str, float] | Sequence[str] | str | float | None = None,
) -> Preparation:
    """Estimate the offsets of raw estimation records (after scaling).

    Parameters
    ----------
    records : IOData or sequence of IOData
        Raw records with the same channels.
    detrend : {"mean", "linear", "none"}, default "mean"
        What to remove from each record: its mean, a straight line fitted over time, or nothing.
    scale : mapping or sequence of "NAME=FACTOR", optional
        Factors for named channels (default 1): units, signs. A matrix
        variable's name scales each of its columns.
    settings : ReadSettings, optional
        How the records were read, kept so that the preparation can read raw files again.
    steering_ratio : float, "NAME=RATIO" strings or mapping, optional
        Steering ratios dividing steering-wheel angles into road-wheel angles
        (a bare number: the only input). With a scale on the same channel
        the factor is scale / ratio.

    Returns
    -------
    Preparation
        The scale factors, and each record's offsets.
    """
    records = as_records(records)
    check_value("detrend", detrend, DETREND)
    first = records[0]
    conversions = _conversions(first, parse_scale(scale), parse_steering_ratio(steering_ratio, first.input_names))
    input_scale, output_scale = _scale_factors(first, conversions)
    offsets = []
    for data in records:
        u_offset, u_slope = _trend(data.t, data.u * input_scale, detrend)
        y_offset, y_slope = _trend(data.t, data.y * output_scale, detrend)
        offsets.append(RecordOffsets(str(data.meta.get("source", "record")), data.n_samples,
                                     u_offset, y_offset, u_slope, y_slope))
    return Preparation(first.input_names, first.output_names, input_scale, output_scale, detrend,
                       tuple(offsets), settings, conversions)


def prepare(
    records: IOData | Sequence[IOData],
    *,
    detrend: str = "mean",
    scale: Mapping[str, float] | Sequence[str] | None = None,
    settings: ReadSettings | None = None,
    steering_ratio: Mapping[str, float] | Sequence[str] | str | float | None = None,
) -> tuple[tuple[IOData, ...], Preparation]:
    """Estimate the preparation of raw records and apply it to each with its own offsets.

    The records are estimation records: before anything is removed or scaled,
    :func:`~identification.data.check_channels` refuses channels that cannot
    identify a model (constant, out of range, an output copying an input).

    Parameters
    ----------
    records : IOData or sequence of IOData
        Raw records with the same channels and sample interval.
    detrend : {"mean", "linear", "none"}, default "mean"
        What to remove from each record.
    scale : mapping or sequence of "NAME=FACTOR", optional
        Channel factors, as for :func:`estimate_preparation`.
    settings : ReadSettings, optional
        How the records were read, kept in the preparation.
    steering_ratio : float, "NAME=RATIO" strings or mapping, optional
        Steering ratios, as for :func:`estimate_preparation`.

    Returns
    -------
    prepared : tuple of IOData
        The records scaled, each with its own offsets removed.
    preparation : Preparation
        What was done, to apply again to validation data.

    Raises
    ------
    InputError
        Bad options, or records that cannot identify a model, naming the channel and the cause.
    """
    records = as_records(records)  # check_channels checks the detrend, before anything is computed
    conversions = _conversions(records[0], parse_scale(scale),
                               parse_steering_ratio(steering_ratio, records[0].input_names))
    input_scale, output_scale = _scale_factors(records[0], conversions)
    check_channels(records, detrend=detrend, input_scale=input_scale, output_scale=output_scale)
    preparation = estimate_preparation(records, detrend=detrend, scale=scale, settings=settings,
                                       steering_ratio=steering_ratio)
    return tuple(preparation.apply(data, i) for i, data in enumerate(records)), preparation


def load_records(
    paths: str | Path | Sequence[str | Path],
    *,
    detrend: str = "mean",
    scale: Mapping[str, float] | Sequence[str] | None = None,
    settings: ReadSettings | None = None,
    steering_ratio: Mapping[str, float] | Sequence[str] | str | float | None = None,
    **options: Any,
) -> tuple[tuple[IOData, ...], Preparation]:
    """Read raw files (:func:`read_record`) and prepare them (:func:`prepare`): the identify command's input.

    Parameters
    ----------
    paths : str, path or sequence of them
        The data files, read alike.
    detrend : {"mean", "linear", "none"}, default "mean"
        What to remove from each record.
    scale : mapping or sequence of "NAME=FACTOR", optional
        Channel factors, as for :func:`estimate_preparation` (the command line's ``--scale``).
    settings : ReadSettings, optional
        How to read the files; ``options`` override its fields.
    steering_ratio : float, "NAME=RATIO" strings or mapping, optional
        Steering ratios, as for :func:`estimate_preparation` (``--steering-ratio``).
    **options
        Fields of :class:`ReadSettings` (``inputs``, ``outputs``, ``time_column``, ``dt``,
        ``resample``, ``decimate``, ``segment``, ``jitter_tolerance``).

    Returns
    -------
    prepared : tuple of IOData
        The prepared records, one per file.
    preparation : Preparation
        What was done, the reading settings included.
    """
    raw, settings = read_raw_records(paths, settings, **options)
    return prepare(raw, detrend=detrend, scale=scale, settings=settings, steering_ratio=steering_ratio)


def read_raw_records(
    paths: str | Path | Sequence[str | Path],
    settings: ReadSettings | None = None,
    **options: Any,
) -> tuple[tuple[IOData, ...], ReadSettings]:
    """Read several files alike (:func:`read_record`), keeping the settings that read them.

    For a hold-out split, split a raw record, :func:`prepare` the estimation
    part with these settings and :func:`prepare_validation` the rest.

    Parameters
    ----------
    paths : str, path or sequence of them
        The data files.
    settings : ReadSettings, optional
        How to read them; ``options`` override its fields.
    **options
        Fields of :class:`ReadSettings`.

    Returns
    -------
    records : tuple of IOData
        The raw records, in the files' units.
    settings : ReadSettings
        The settings, with the channels a workbench HDF5 record chose.
    """
    if isinstance(paths, (str, Path)):
        paths = [paths]
    if not paths:
        raise InputError("give at least one data file")
    settings = ReadSettings(**options) if settings is None else replace(settings, **options)
    raw = tuple(read_record(path, settings) for path in paths)
    if not settings.inputs or not settings.outputs:  # a workbench HDF5 record chose its own channels
        settings = replace(settings, inputs=raw[0].input_names, outputs=raw[0].output_names)
    return raw, settings


def prepare_validation(
    data: IOData | str | Path,
    preparation: Preparation,
    *,
    record: int | None = None,
    own_offsets: bool = False,
    channels: tuple[Sequence[str], Sequence[str]] | None = None,
) -> IOData:
    """Prepare validation data exactly as the estimation data were prepared.

    Parameters
    ----------
    data : IOData or path
        A raw record (for example the held-out tail of a raw estimation file,
        split *before* preparing), or a file read with the preparation's
        reading settings (same channels, time column, resampling, decimation;
        the segment is not applied, since it selected the estimation part).
    preparation : Preparation
        Of the estimation data; its scale factors and the model's offsets are applied.
    record : int, optional
        Apply the offsets of estimation record ``record`` instead (re-applying a
        model to its own raw estimation file).
    own_offsets : bool
        Remove the record's own offsets, estimated as the estimation records'
        were (``detrend``), instead of the model's: for a separate experiment,
        whose operating point is its own just as each estimation record's is.
    channels : (inputs, outputs), optional
        The names under which a file holds the model's channels, in the
        model's order, where they differ from the estimation file's (a
        MATLAB file with ``uVal``/``yVal`` beside ``uEst``/``yEst``).

    Returns
    -------
    IOData
        Prepared, in the model's units.
    """
    if not isinstance(data, IOData):
        if preparation.settings is None:
            raise InputError("this preparation was estimated on records in memory: it holds no reading settings "
                             "to read a file with")
        segment = preparation.settings.segment if record is not None else None
        settings = replace(preparation.settings, segment=segment)
        if channels is not None:
            inputs, outputs = (tuple(names) for names in channels)
            if len(inputs) != len(preparation.input_names) or len(outputs) != len(preparation.output_names):
                raise InputError(f"the validation channels ({', '.join(inputs)} -> {', '.join(outputs)}) must "
                                 f"match the model's {len(preparation.input_names)} inputs and "
                                 f"{len(preparation.output_names)} outputs in number")
            settings = replace(settings, inputs=inputs, outputs=outputs)
        data = read_record(data, settings)
        if channels is not None:  # the model's names for the same channels
            data = replace(data, input_names=preparation.input_names, output_names=preparation.output_names)
    if own_offsets:
        factors = {**dict(zip(preparation.input_names, map(float, preparation.input_scale))),
                   **dict(zip(preparation.output_names, map(float, preparation.output_scale)))}
        preparation._check(data)
        return estimate_preparation(data, detrend=preparation.detrend, scale=factors).apply(data, 0)
    return preparation.apply(data, record)
