"""What a model's simulation and frequency response return: frozen values with their data and a ``.plot()``.

:class:`TimeResponse` is a record (it is an :class:`~identification.data.IOData`, so everything that takes a
record takes it): the record's time and inputs, the model's outputs (and states, where the model gives them)
and, where the simulation answered a measured record, that record's outputs as :attr:`TimeResponse.measured`.
:class:`FrequencyResponse` holds ``C (p I - A)^-1 B + D`` at each frequency with the frequencies, the channel
names and the sample interval of a discrete-time model; it converts to the complex array ``(n_f, n_y, n_u)``
that the models' ``frequency_response`` used to return (``numpy.asarray(response)``, ``response[:, 0, 0]``).

Both draw themselves with ``.plot()``, which returns the matplotlib Figure: onto the axes given (``ax``), or
onto a new Figure with its own canvas. Nothing here imports ``matplotlib.pyplot`` or shows a window, so the
values are as safe in scripts, tests and servers as the arrays they hold.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..data import IOData
from ..errors import InputError

__all__ = ["TimeResponse", "FrequencyResponse", "simulated_response"]

_FIGURE_WIDTH = 7.0  # [in] legible on an A4 page at 100 %
_ROW_HEIGHT = 1.8  # [in] per output


def _new_figure(rows: int, columns: int, *, sharex: bool = True) -> tuple[Any, np.ndarray]:
    """A Figure on its own Agg canvas (no pyplot) and its ``rows`` x ``columns`` axes."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(max(_FIGURE_WIDTH, 2.6 * columns), max(3.0, 1.0 + _ROW_HEIGHT * rows)),
                 layout="constrained")
    FigureCanvasAgg(fig)
    return fig, fig.subplots(rows, columns, sharex=sharex, squeeze=False)


def _given_axes(ax: Any, count: int, what: str) -> list[Any]:
    """``ax`` as a list of ``count`` axes: one Axes serves every channel, a sequence gives one each."""
    from matplotlib.axes import Axes

    if isinstance(ax, Axes):
        return [ax] * count
    axes = list(np.ravel(np.asarray(ax, dtype=object)))
    if len(axes) != count or not all(isinstance(item, Axes) for item in axes):
        raise InputError(f"ax must be one matplotlib Axes or {count} of them ({what}); got {len(axes)} items")
    return axes


def _label(name: str, unit: str | None) -> str:
    unit = "" if unit is None else str(unit).strip()
    return name if unit in ("", "-") else f"{name} ({unit})"


@dataclass(frozen=True, eq=False)
class TimeResponse(IOData):
    """A model's simulated outputs over a record's time and inputs: a record with the measurement it answers.

    Parameters
    ----------
    t : array_like, shape (N,)
        Sample times (s), as the record's.
    u : array_like, shape (N, n_u)
        The inputs the model was driven by.
    y : array_like, shape (N, n_y)
        The model's outputs.
    x : array_like, shape (N, n_states), optional
        Its states, where it gave them.
    input_names, output_names, state_names : sequence of str, optional
        Column names, as :class:`~identification.data.IOData`'s.
    input_units, output_units, state_units : sequence of str, optional
        Units of each column, as :class:`~identification.data.IOData`'s.
    meta : mapping, optional
        Free-form metadata.
    measured : array_like (N, n_y), optional
        The outputs of the record the model was driven by, for comparison; None where there were none
        to compare with (a record of another size, a simulation from bare arrays).

    Examples
    --------
    >>> import numpy as np
    >>> from vehid.identification import ContinuousModel, IOData
    >>> lag = ContinuousModel([[-2.0]], [[2.0]], [[1.0]], [[0.0]])  # a first-order lag of unit gain
    >>> record = IOData(t=np.arange(500) * 0.01, u=np.ones((500, 1)), y=np.ones((500, 1)))
    >>> response = lag.simulate(record)
    >>> round(float(response.y[-1, 0]), 4), round(float(response.residuals[-1, 0]), 4)
    (1.0, 0.0)
    >>> fig = response.plot()
    >>> len(fig.axes)
    1
    """

    measured: np.ndarray | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.measured is not None:
            measured = np.array(self.measured, dtype=float)
            if measured.ndim == 1:
                measured = measured[:, None]
            if measured.shape != self.y.shape:
                raise InputError(f"the measured outputs have shape {measured.shape}; the response's {self.y.shape}")
            measured.setflags(write=False)
            object.__setattr__(self, "measured", measured)

    @property
    def residuals(self) -> np.ndarray | None:
        """``measured - y`` (N, n_y); None without a measurement."""
        return None if self.measured is None else self.measured - self.y

    def __getitem__(self, index: slice) -> "TimeResponse":
        """Slice in time, the measurement with the rest: ``response[100:200]``."""
        if not isinstance(index, slice):
            raise TypeError("a response supports slicing in time only, e.g. response[100:200]")
        return self.replace(t=self.t[index], u=self.u[index], y=self.y[index],
                            x=None if self.x is None else self.x[index],
                            measured=None if self.measured is None else self.measured[index])

    def select_outputs(self, names: Sequence[str]) -> "TimeResponse":
        """Keep only the named outputs and their measurement.

        Parameters
        ----------
        names : sequence of str
            Output names, in the order wanted.

        Returns
        -------
        TimeResponse
            The response with those outputs.
        """
        index = [self._column(self.output_names, name, "output") for name in names]
        return self.replace(y=self.y[:, index], output_names=tuple(self.output_names[i] for i in index),
                            output_units=tuple(self.output_units[i] for i in index),
                            measured=None if self.measured is None else self.measured[:, index])

    def plot(self, *, ax: Any = None, label: str = "model", measured: bool = True, title: str | None = None) -> Any:
        """Each output against time, the measurement (black) under the model's line.

        Parameters
        ----------
        ax : matplotlib Axes or sequence of Axes, optional
            One Axes takes every output; a sequence takes one output each (n_y of them). Default: a new
            Figure with one row per output.
        label : str
            The model's lines' legend entry.
        measured : bool
            Draw the measurement where there is one.
        title : str, optional
            The Figure's title (only on a new Figure).

        Returns
        -------
        matplotlib.figure.Figure
            The Figure drawn into.
        """
        if ax is None:
            fig, grid = _new_figure(self.n_y, 1)
            axes = list(grid[:, 0])
            if title:
                fig.suptitle(title)
        else:
            axes = _given_axes(ax, self.n_y, "one per output")
            fig = axes[0].figure
        shared = len(set(map(id, axes))) == 1 and self.n_y > 1
        for i, axis in enumerate(axes):
            name = self.output_names[i]
            if measured and self.measured is not None:
                axis.plot(self.t, self.measured[:, i], color="black", linewidth=1.4,
                          label=f"measured {name}" if shared else "measured")
            axis.plot(self.t, self.y[:, i], linewidth=1.1, label=f"{label} {name}" if shared else label)
            axis.set_ylabel(_label("output" if shared else name, None if shared else self.output_units[i]))
            axis.grid(True, alpha=0.3)
        axes[-1].set_xlabel("time (s)")
        axes[0].legend(fontsize=8)
        return fig

    def to_hdf5(self, group: Any) -> None:
        """Write into an open HDF5 group: the record as :class:`IOData` writes it, and ``measured``.

        Parameters
        ----------
        group : h5py.Group
            The open group, written into.
        """
        super().to_hdf5(group)
        if self.measured is not None:
            group.create_dataset("measured", data=self.measured).attrs["units"] = list(self.output_units)

    @classmethod
    def from_hdf5(cls, group: Any) -> "TimeResponse":
        """Read what :meth:`to_hdf5` wrote.

        Parameters
        ----------
        group : h5py.Group
            The open group.

        Returns
        -------
        TimeResponse
            The response.
        """
        record = IOData.from_hdf5(group)
        measured = group["measured"][()] if "measured" in group else None
        return cls(record.t, record.u, record.y, record.x, record.input_names, record.output_names,
                   record.state_names, record.input_units, record.output_units, record.state_units, record.meta,
                   measured)


def simulated_response(record: IOData, y: np.ndarray, *, x: np.ndarray | None = None,
                       output_names: Sequence[str] | None = None, state_names: Sequence[str] | None = None,
                       meta: dict[str, Any] | None = None) -> TimeResponse:
    """The :class:`TimeResponse` of outputs ``y`` (N, n_y) simulated over ``record``'s time and inputs.

    Parameters
    ----------
    record : IOData
        The record that drove the model.
    y : ndarray (N, n_y)
        The model's outputs.
    x : ndarray (N, n_states), optional
        The model's states.
    output_names, state_names : sequence of str, optional
        The model's names; the outputs default to the record's where it has ``n_y`` outputs.
    meta : dict, optional
        Added to the record's ``meta``.

    Returns
    -------
    TimeResponse
        With the record's outputs as ``measured`` (and their names and units) where it has ``n_y`` of them.
    """
    y = np.asarray(y, dtype=float)
    same = record.n_y == y.shape[1]
    names = tuple(output_names) if output_names is not None and len(output_names) == y.shape[1] else None
    return TimeResponse(
        t=record.t, u=record.u, y=y, x=x, input_names=record.input_names,
        output_names=names or (record.output_names if same else None),
        state_names=None if x is None else state_names, input_units=record.input_units,
        output_units=record.output_units if same else None, meta={**dict(record.meta), **dict(meta or {})},
        measured=record.y if same else None)


@dataclass(frozen=True, eq=False)
class FrequencyResponse:
    """A model's frequency response: ``G(f)`` from every input to every output at each frequency.

    It converts to the complex array ``(n_f, n_y, n_u)`` (``numpy.asarray(response)``, ``response[:, i, j]``,
    ``len(response)``), the form the models' ``frequency_response`` returned before it returned this value.

    Parameters
    ----------
    frequencies_hz : array_like (n_f,)
        Frequencies (Hz).
    response : array_like (n_f, n_y, n_u), complex
        ``G`` at each frequency: ``C (p I - A)^-1 B + D`` with ``p = j 2 pi f`` (continuous time) or
        ``p = exp(j 2 pi f dt)`` (discrete time).
    dt : float, optional
        The sample interval of a discrete-time model (its response repeats every ``1 / dt``); None if continuous.
    input_names, output_names : sequence of str, optional
        Default ``u1, ...`` and ``y1, ...``.
    schedule : float or tuple of float, optional
        The value of the scheduling variable (or each signal's) the response holds at (a scheduled
        model's), for the title.

    Examples
    --------
    >>> import numpy as np
    >>> from vehid.identification import ContinuousModel
    >>> lag = ContinuousModel([[-1.0]], [[1.0]], [[1.0]], [[0.0]])
    >>> response = lag.frequency_response([0.0, 1 / (2 * np.pi)])
    >>> np.round(response.magnitude[:, 0, 0], 4), np.round(response.phase_deg[:, 0, 0], 1)
    (array([1.    , 0.7071]), array([  0., -45.]))
    >>> np.round(response[1, 0, 0], 6)  # indexes like the complex array it holds
    np.complex128(0.5-0.5j)
    """

    frequencies_hz: np.ndarray
    response: np.ndarray
    dt: float | None = None
    input_names: tuple[str, ...] | None = None
    output_names: tuple[str, ...] | None = None
    schedule: float | tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if self.schedule is not None:
            values = np.asarray(self.schedule, dtype=float).ravel()
            object.__setattr__(self, "schedule", float(values[0]) if values.size == 1 else tuple(values.tolist()))
        frequencies = np.array(self.frequencies_hz, dtype=float).ravel()
        response = np.array(self.response, dtype=complex)
        if response.ndim != 3 or response.shape[0] != frequencies.size:
            raise InputError(f"a frequency response is (n_f, n_y, n_u) at {frequencies.size} frequencies; "
                             f"got shape {response.shape}")
        for name, array in (("frequencies_hz", frequencies), ("response", response)):
            array.setflags(write=False)
            object.__setattr__(self, name, array)
        n_y, n_u = response.shape[1:]
        for name, count, stem in (("input_names", n_u, "u"), ("output_names", n_y, "y")):
            names = getattr(self, name)
            names = tuple(f"{stem}{i + 1}" for i in range(count)) if not names else tuple(str(n) for n in names)
            if len(names) != count:
                raise InputError(f"{len(names)} {name.replace('_', ' ')} for {count} channels")
            object.__setattr__(self, name, names)

    @property
    def omega(self) -> np.ndarray:
        """Angular frequencies ``2 pi f`` (rad/s)."""
        return 2 * np.pi * self.frequencies_hz

    @property
    def magnitude(self) -> np.ndarray:
        """``|G|`` (n_f, n_y, n_u)."""
        return np.abs(self.response)

    @property
    def phase_deg(self) -> np.ndarray:
        """The phase (deg), unwrapped along frequency (n_f, n_y, n_u)."""
        return np.degrees(np.unwrap(np.angle(self.response), axis=0))

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(n_f, n_y, n_u)``."""
        return self.response.shape

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        return self.response if dtype is None else self.response.astype(dtype)

    def __getitem__(self, index: Any) -> Any:
        return self.response[index]

    def __len__(self) -> int:
        return int(self.response.shape[0])

    @property
    def real(self) -> np.ndarray:
        """The response's real part, as the array's."""
        return self.response.real

    @property
    def imag(self) -> np.ndarray:
        """The response's imaginary part, as the array's."""
        return self.response.imag

    def conj(self) -> np.ndarray:
        """Return the complex conjugate of the response, as the array's.

        Returns
        -------
        ndarray of complex, shape (F, n_y, n_u)
            The conjugate response.
        """
        return self.response.conj()

    def plot(self, *, ax: Any = None, label: str | None = None, title: str | None = None) -> Any:
        """Bode plot: magnitude (log-log) and unwrapped phase against frequency, each input a line.

        Parameters
        ----------
        ax : pair of matplotlib Axes, or 2 x n_y of them, optional
            Where to draw: ``(magnitude, phase)`` take every output, or a ``(2, n_y)`` grid one column per
            output. Default: a new Figure with that grid.
        label : str, optional
            Prefix of the legend entries (e.g. the model's name); each line is named by its input.
        title : str, optional
            The Figure's title (only on a new Figure).

        Returns
        -------
        matplotlib.figure.Figure
            The Figure drawn into.
        """
        n_f, n_y, n_u = self.shape
        positive = self.frequencies_hz > 0
        if np.count_nonzero(positive) < 2:
            raise InputError("a Bode plot needs at least two positive frequencies")
        if ax is None:
            fig, grid = _new_figure(2, n_y)
            if title:
                fig.suptitle(title)
        else:
            items = np.asarray(ax, dtype=object)
            columns = 1 if items.size == 2 else n_y
            grid = np.array(_given_axes(ax, 2 * columns, "magnitude and phase, per output"),
                            dtype=object).reshape(2, columns)
            fig = grid[0, 0].figure
        f = self.frequencies_hz[positive]
        magnitude, phase = self.magnitude[positive], self.phase_deg[positive]
        for i in range(n_y):
            column = i if grid.shape[1] == n_y else 0
            top, bottom = grid[0, column], grid[1, column]
            for j in range(n_u):
                name = self.input_names[j]
                if grid.shape[1] != n_y:  # every output on one pair of axes: each line says which
                    name = f"{name} to {self.output_names[i]}"
                text = f"{label}: {name}" if label else name
                lines = top.loglog(f, magnitude[:, i, j], linewidth=1.3, label=text)
                bottom.semilogx(f, phase[:, i, j], linewidth=1.3, color=lines[0].get_color())
            if grid.shape[1] == n_y:
                top.set_title(self.output_names[i], fontsize=10)
            top.set_ylabel("|G|")
            bottom.set_ylabel("phase (deg)")
            bottom.set_xlabel("frequency (Hz)")
            for axis in (top, bottom):
                axis.grid(True, which="both", alpha=0.3)
                if self.dt is not None:  # a discrete model's response mirrors beyond here
                    axis.axvline(0.5 / self.dt, color="grey", linestyle=":", linewidth=1.0)
        grid[0, 0].legend(fontsize=8)
        if self.schedule is not None and ax is None and not title:
            values = np.atleast_1d(self.schedule)
            fig.suptitle(f"at schedule value {', '.join(f'{value:g}' for value in values)}")
        return fig
