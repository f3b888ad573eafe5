"""Speed-scheduled modal models from a record whose scheduling variable varies (an LPV IEKF).

Every free coefficient of the modal model (each mode's sigma and omega, B, C and D, in the input gauge
of :mod:`vehid.identification.models.scheduled`) is a piecewise-linear spline in a measured scheduling channel
``s(t)`` (a car's speed) over a grid of knots; the spline ordinates, one full set of modal parameters
per knot, join the states of the Identifying EKF (Best & Bogdanski 2017, eq. 7-8), as the
spline-nonlinear model's node ordinates do (section 5), with exact CasADi Jacobians and the compiled
pass of :mod:`vehid.identification.filtering.iekf_pass`. Piecewise-linear interpolation of the coefficients
between knots is what :class:`~identification.models.scheduled.ScheduledModalModel` does between grid models,
so the result is one: the knots are its grid, the ordinates its grid models.

* **Start**: knot by knot, a fast linear estimate (the data start of
  :mod:`vehid.identification.filtering.start`: subspace and band candidates, the best-simulating kept) of
  the samples whose schedule lies nearest that knot, in the input gauge so that knots are comparable; a
  knot whose samples are too few, too weakly excited or simulated better by the record's unscheduled model
  takes its nearest neighbour's. Where no knot has a local estimate, or the local family simulates the
  record worse than the unscheduled model given as ``start`` repeated at every knot, that is the start.
  The unscheduled model of a record over a range of speeds is a compromise between them (on a car's speed
  ramp one mode damped 0.998 where the car's is 0.66-0.90): the filter started from it ended near critical
  damping at every knot, started locally it reached the damping of models identified at fixed speeds and
  fitted better. The output offsets at the knots (module notes of
  :mod:`vehid.identification.models.scheduled`) start at zero.
* **Knots**: by default at evenly spaced quantiles of the schedule (:func:`default_grid`), so that
  every knot is supported by data, merged where the quantiles crowd them together (a record that dwells
  at a few values); the coefficients are held at the end knots' values beyond them. How much of the
  record each knot rests on is kept with the family (:func:`knot_coverage`, ``meta["knot_coverage"]``):
  a knot with too few samples, or too little input, has ordinates extrapolated from its neighbours'.
* **Units**: as the linear filter's invariant settings (:mod:`vehid.identification.filtering.iekf`): signals
  divided by their RMS, time counted in samples, ``p`` per dominant time constant of the start,
  Q shrinking from pass to pass (larger and slower than the linear filter's: :data:`DEFAULT_P`),
  R from each output's measured noise.
* **Covariance**: that of the ordinates as a fit of the simulation errors, by the delete-one-block
  jackknife of the fit where the record allows (:func:`~identification.assessment.uncertainty.fit_covariance`),
  the simulation's Jacobian by central differences of the compiled simulation; the family's
  ``meta["uncertainty_method"]`` says how.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import casadi as ca
import numpy as np

from ..blas import on_one_blas_thread
from ..data import IOData, as_records
from ..choices import SCHEDULE_GRID, SCHEDULE_KNOT_COUNT
from ..errors import DivergenceError, InputError, WorkbenchError
from ..optionspec import check_value
from ..models.transition import check_discretization
from .filter_models import FilterModel
from .iekf import P_DECAY_FLOOR, data_measurement_noise, signal_scales
from .iekf_pass import compiled_pass
from ..assessment.metrics import percentage_explanation
from ..models.modal import ModalModel
from ..models.modal_structure import ModalStructure
from .rinse import Assessment, PassHistory, PassRecord, RinseHooks, check_filter_options, check_records, rinse
from ..models.scheduled import ScheduledModalModel
from ..models.scheduled_gauge import (gauge_parameters, input_gauge, interpolation_weights, knot_size,
                                      scheduled_matrices, scheduled_step)
from ..assessment.uncertainty import fit_covariance

__all__ = ["ScheduledFilterModel", "ScheduledIEKFOptions", "ScheduledIEKFResult", "Runs", "default_grid",
           "identify_scheduled", "knot_cells", "KnotCoverage", "knot_coverage", "MIN_KNOT_SPACING",
           "refine_by_simulation", "scheduled_simulation_covariance", "with_simulation_covariance", "DEFAULT_KNOTS",
           "DEFAULT_P", "DEFAULT_P_DECAY", "MIN_KNOTS", "MAX_KNOTS"]

from vehid.identification.choices import SCHEDULE_DEFAULT_KNOTS as DEFAULT_KNOTS  # noqa: E402
from vehid.identification.choices import SCHEDULE_MAX_KNOTS as MAX_KNOTS  # noqa: E402
from vehid.identification.choices import SCHEDULE_MIN_KNOTS as MIN_KNOTS  # noqa: E402
# the end knots sit at these quantiles of the schedule, not at its extremes: a knot at the
# record's single fastest sample would rest on a handful of samples
_END_QUANTILES = (0.02, 0.98)
#: The default grid's knots are at least this fraction of the even spacing apart (:func:`default_grid`):
#: knots crowded closer see nearly the same samples, so their ordinates are told apart only by the
#: schedule's small difference between them, while the rest of the range goes without. Quantiles of a
#: race car's oval log put three of five knots within 1.3 m/s of a 20 m/s range (gaps of a fifth of the
#: even spacing and less). A track log's quantile knots sit closest where the car is slow, which is where
#: a car's dynamics change fastest with speed (the single-track model's coefficients go as 1/V): the
#: closest gaps of the committed race-car log (whole, and its first 60 %) and of its 550 s drive's first
#: 70 %, 0.46-0.51 of the even spacing, stand (merged at half the even spacing, their held-out fits fell by
#: up to 4.6 points).
MIN_KNOT_SPACING = 0.25
# p per dominant time constant and its decay per pass, larger and slower than the linear filter's
# (1e-4, 0.7): the ordinates start all alike from a model of the whole record, which for a car that
# changes speed is one averaged over speeds, often near a double pole, where the outputs barely depend
# on a pair's omega; the filter must travel far from it. On a single-track model driven over 10-30 m/s,
# the linear filter's settings left every mode near critical damping (0.99 against the true 0.68-0.96);
# p = 1e-2 shrinking by 0.9 per pass reached them within 0.03 (tests/test_scheduled_iekf.py)
from vehid.identification.choices import SCHEDULED_DEFAULT_P as DEFAULT_P  # noqa: E402
DEFAULT_P_DECAY = 0.9
_DEGENERATE_SPAN = 1e-6  # a schedule range narrower than this, relative to its magnitude, did not vary
_DIFFERENCE_STEP = 1e-6  # relative step of the central differences of the simulation
# A knot's own start (ScheduledIEKFOptions.local_starts) needs samples enough to say its modes: this many
# time constants of the start's slowest mode and this many samples per parameter of the structure, and
# an input there of at least this fraction of the record's RMS (a stretch driven straight says nothing)
LOCAL_MIN_TIME_CONSTANTS = 10.0
LOCAL_MIN_SAMPLES_PER_PARAMETER = 20
LOCAL_MIN_EXCITATION = 0.1
# the simulation method that matches each discretization of the filter
HOLD_OF = {"exact": "foh", "exact-zoh": "zoh", "euler": "euler"}


def default_grid(schedule: Any, count: int = DEFAULT_KNOTS) -> np.ndarray:
    """At most ``count`` knots at evenly spaced quantiles of the schedule, the ends at its 2nd and 98th
    percentiles, none closer than :data:`MIN_KNOT_SPACING` of the even spacing.

    Quantiles rather than an even spacing put the knots where the record
    spends its time, so that each ordinate is supported by data. Where the
    record dwells, the quantiles crowd together: the closest two knots are
    then merged, until every gap is wide enough. An end knot keeps its place
    and its crowded neighbour goes (the range stays covered); two interior
    knots become one at the quantile midway between theirs, so that it rests
    on the samples of both.

    Raises
    ------
    InputError
        For a bad count, non-finite samples, or a schedule that barely varies
        (no two distinct knots).
    """
    schedule = np.asarray(schedule, dtype=float).ravel()
    count = check_value("count", count, SCHEDULE_KNOT_COUNT)
    if schedule.size < 2 or not np.all(np.isfinite(schedule)):
        raise InputError("the schedule channel needs at least two finite samples")
    levels = list(np.linspace(*_END_QUANTILES, int(count)))
    grid = np.quantile(schedule, levels)
    span = grid[-1] - grid[0]
    if not span > _DEGENERATE_SPAN * max(abs(grid[0]), abs(grid[-1]), 1e-300):
        raise InputError(f"the schedule channel barely varies ({grid[0]:.6g}..{grid[-1]:.6g} between its 2nd and "
                         "98th percentiles): a scheduled model needs a record over a range of its values")
    closest = MIN_KNOT_SPACING * span / (int(count) - 1)
    while len(levels) > MIN_KNOTS:
        gaps = np.diff(grid)
        k = int(np.argmin(gaps))
        if gaps[k] >= closest:
            break
        if k == 0:
            del levels[1]
        elif k + 1 == len(levels) - 1:
            del levels[k]
        else:
            levels[k:k + 2] = [0.5 * (levels[k] + levels[k + 1])]
        grid = np.quantile(schedule, levels)
    return grid


def check_grid(grid: Any) -> np.ndarray:
    """A given grid as an increasing float array of ``MIN_KNOTS..MAX_KNOTS`` finite values; OptionError otherwise."""
    return np.array(check_value("grid", tuple(np.asarray(grid, dtype=float).ravel()), SCHEDULE_GRID))


@dataclass(frozen=True)
class ScheduledFilterModel(FilterModel):
    """The scheduled family as a filter model: inputs then the schedule, the knots as constants."""

    structure: ModalStructure
    knots: int

    @property
    def n_states(self) -> int:
        return self.structure.n

    @property
    def n_theta(self) -> int:
        return self.knots * knot_size(self.structure)

    @property
    def n_u(self) -> int:
        return self.structure.n_u + 1

    @property
    def n_y(self) -> int:
        return self.structure.n_y

    @property
    def n_constants(self) -> int:
        return self.knots

    def cache_key(self) -> str:
        return f"scheduled-modal:{self.structure.to_dict()}:{self.knots}"

    def transition(self, x: ca.SX, theta: ca.SX, u0: ca.SX, u1: ca.SX, dt: float, discretization: str,
                   constants: ca.SX) -> ca.SX:
        check_discretization(discretization)
        return scheduled_step(self.structure, x, u0, u1, theta, constants, dt, discretization)[0]

    def output(self, x: ca.SX, theta: ca.SX, u: ca.SX, constants: ca.SX) -> ca.SX:
        n_u = self.structure.n_u
        weights = interpolation_weights(u[n_u], [constants[k] for k in range(self.knots)])
        _, _, C, D, offset = scheduled_matrices(self.structure, theta, weights)
        return ca.mtimes(C, x) + ca.mtimes(D, u[:n_u]) + offset


@dataclass(frozen=True)
class ScheduledIEKFOptions:
    """Settings of the scheduled IEKF.

    Parameters
    ----------
    knots : int
        Knots of the default grid (:func:`default_grid`), 2..9.
    grid : tuple of float, optional
        The knots themselves, increasing (overrides ``knots``).
    p : float
        ``Q = p I'`` per dominant time constant of the start on the
        normalised ordinates (as the linear filter's invariant settings).
    p_decay : float
        Q shrinks by this factor per pass (1: constant), down to the linear filter's floor.
    passes, min_passes : int
        Largest number of passes, and the fewest before the fit may stop the run: while Q is still
        large the fit can pause on the way (a run on the single-track record stopped at pass 10,
        0.037 from the true damping, where twenty or more passes came within 0.028).
    fit_tolerance : float
        Stop when the mean R (percent) changes by less than this between passes.
    discretization, covariance : str
        As for the linear filter.
    stable : bool
        Keep every knot stable: after each pass a pole that crossed into the right half-plane at a knot is
        reflected back (its sigma's sign flipped), as the linear filter refuses an unstable model. The
        filter's innovations are corrected by the measurements, so a knot where the record dwells briefly
        can drift unstable without the filter noticing; the simulation from rest then blows up.
    refine_iterations : int
        Levenberg-Marquardt steps on the simulation errors after the passes (:func:`refine_by_simulation`),
        from whichever of the filter's family, its start and the given unscheduled start at every knot
        simulates the record better; 0: none. On a
        race car's 48 s log the filter's family simulated worse than its unscheduled start (its
        one-step errors were small while knots drifted); ten steps from the start raised the held-out
        fit of the lateral acceleration from 64 % to 72 %.
    local_starts : bool
        Start each knot from a fast linear estimate of the samples near it (module notes), kept where
        that family simulates the record better than ``start`` at every knot; False: ``start`` at
        every knot.
    """

    knots: int = DEFAULT_KNOTS
    grid: tuple[float, ...] | None = None
    p: float = DEFAULT_P
    p_decay: float = DEFAULT_P_DECAY
    passes: int = 40
    min_passes: int = 20
    fit_tolerance: float = 1e-4
    discretization: str = "exact"
    covariance: str = "joseph"
    stable: bool = True
    refine_iterations: int = 10
    local_starts: bool = True

    def __post_init__(self) -> None:
        check_value("knots", self.knots, SCHEDULE_KNOT_COUNT)
        if self.grid is not None:
            object.__setattr__(self, "grid", tuple(float(g) for g in check_grid(self.grid)))
        check_filter_options(self.p, self.passes, self.discretization, self.covariance)
        if isinstance(self.refine_iterations, bool) or int(self.refine_iterations) != self.refine_iterations or \
                self.refine_iterations < 0:
            raise InputError(f"refine_iterations must be a whole number >= 0; got {self.refine_iterations!r}")
        if not 0 < self.p_decay <= 1:
            raise InputError(f"p_decay must lie in (0, 1]; got {self.p_decay!r}")


@dataclass(frozen=True, eq=False)
class ScheduledIEKFResult(PassHistory):
    """The identified family, its start, one record per pass and the filter's final P (filter units).

    Attributes
    ----------
    model : ScheduledModalModel
        The identified family.
    start : ScheduledModalModel
        The family the filter started from.
    options : ScheduledIEKFOptions
        The settings used.
    history : tuple of PassRecord
        One record per pass.
    P : ndarray
        The filter's final covariance of the family's parameters (filter units).
    start_fit : ndarray, shape (n_y,)
        R (eq. 17) per output of the start family, percent.
    stop_reason : str
        ``"converged"``, ``"passes"`` or ``"diverged: ..."``.
    seconds : float
        Run time (s).
    meta : dict
        Provenance; ``fit_percent`` where the fits were refined after the passes.
    """

    model: ScheduledModalModel
    start: ScheduledModalModel
    options: ScheduledIEKFOptions
    history: tuple[PassRecord, ...]
    P: np.ndarray
    start_fit: np.ndarray
    stop_reason: str
    seconds: float
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def fit_percent(self) -> np.ndarray:
        """R per output (eq. 17) of the final family simulated from rest along the record's schedule."""
        if "fit_percent" in self.meta:  # refined after the passes
            return self.meta["fit_percent"]
        return self.history[-1].fit_continuous if self.history else self.start_fit


def _unit_scale(structure: ModalStructure, input_scale: np.ndarray, output_scale: np.ndarray, dt: float) -> np.ndarray:
    """Per parameter of one knot: original units per filter unit (signals / RMS, time in samples).

    In the input gauge the first input's B entries are fixed, so a change of
    time unit or of the first input's scale moves into the states and C:
    sigma/omega scale by 1/dt, B's other columns by ``Su_0 / Su_j``, C's row i
    by ``Sy_i / (Su_0 dt)``, D by ``Sy_i / Su_j``.
    """
    n, n_u, n_y = structure.n, structure.n_u, structure.n_y
    modal = np.full(n, 1.0 / dt)
    B = np.column_stack([np.ones(n), np.tile(input_scale[0] / input_scale[1:], (n, 1))])
    C = np.tile((output_scale / (input_scale[0] * dt))[:, None], (1, n))
    D = output_scale[:, None] / input_scale[None, :]
    return np.concatenate([gauge_parameters(modal, B, C, D), output_scale])


def _time_weights(structure: ModalStructure, ratio: float) -> np.ndarray:
    """Per parameter of one knot: how it scales with the unit of time (input gauge: sigma, omega and C)."""
    n, n_u, n_y = structure.n, structure.n_u, structure.n_y
    return np.concatenate([gauge_parameters(np.full(n, ratio), np.ones((n, n_u)), np.full((n_y, n), ratio),
                                            np.ones((n_y, n_u))), np.ones(n_y)])


@dataclass(frozen=True, eq=False)
class Runs:
    """Records of one sample interval and their schedules, simulated each from rest and joined in time order.

    A drive cut into runs (a stop between them, a stretch left out) is several records; a family's
    simulation error over them is each run's, from its own start, one after the other.
    """

    records: tuple[IOData, ...]
    schedules: tuple[np.ndarray, ...]

    @classmethod
    def of(cls, data: IOData | Sequence[IOData] | "Runs", schedule: Any = None) -> "Runs":
        """One record and its schedule (N,), or records and one schedule each; InputError where they differ."""
        if isinstance(data, Runs):
            return data
        records = as_records(data)
        schedules = [schedule] if isinstance(data, IOData) else list(schedule)
        if len(schedules) != len(records):
            raise InputError(f"{len(schedules)} schedules for {len(records)} records: give one per record")
        checked = []
        for record, values in zip(records, schedules):
            values = np.asarray(values, dtype=float).ravel()
            if values.shape != (record.n_samples,):
                raise InputError(f"the schedule has {values.size} samples; the record has {record.n_samples}")
            if not np.all(np.isfinite(values)):
                raise InputError("the schedule channel contains a non-finite value (NaN or inf)")
            checked.append(values)
        return cls(records, tuple(checked))

    @property
    def y(self) -> np.ndarray:
        """The measured outputs, the runs one after the other."""
        return self.records[0].y if len(self.records) == 1 else np.vstack([record.y for record in self.records])

    @property
    def schedule(self) -> np.ndarray:
        """The schedule, the runs one after the other."""
        return self.schedules[0] if len(self.schedules) == 1 else np.concatenate(self.schedules)

    @property
    def joined(self) -> IOData:
        """Every sample as one record (for what takes samples wherever they lie: knots, a knot's samples)."""
        if len(self.records) == 1:
            return self.records[0]
        first = self.records[0]
        u = np.vstack([record.u for record in self.records])
        return first.replace(t=first.t[0] + first.dt * np.arange(u.shape[0]), u=u, y=self.y)

    def simulate(self, model: ScheduledModalModel, method: str) -> np.ndarray:
        """The family's outputs on every run, each simulated from rest along its schedule, joined."""
        parts = [model.simulate_outputs(record.u, record.dt, schedule=values, method=method)
                 for record, values in zip(self.records, self.schedules)]
        return parts[0] if len(parts) == 1 else np.vstack(parts)


def scheduled_simulation_covariance(model: ScheduledModalModel, data: IOData | Sequence[IOData], schedule: Any,
                                    method: str = "foh", *, jackknife: bool = True,
                                    form: str = "linearised") -> np.ndarray | None:
    """The covariance of a family's parameters as a fit of its simulation errors on a record (or several
    records, each simulated from rest along its schedule: ``schedule`` then one array per record; or
    :class:`Runs`, ``schedule`` None).

    :func:`~identification.assessment.uncertainty.fit_covariance` of the
    errors from rest (the delete-one-block jackknife where the record
    allows, its replicates in ``form``; ``jackknife=False``: the formal covariance of white residuals),
    the Jacobian by central differences of the compiled simulation (steps of ``1e-6`` of each
    parameter, or of the largest of its kind where it is near zero). None where the simulation is not
    finite.
    """
    found = _simulation_fit(model, data, schedule, method, jackknife=jackknife, form=form)
    return None if found is None else found[0]


def with_simulation_covariance(model: ScheduledModalModel, data: IOData | Sequence[IOData], schedule: Any,
                               method: str = "foh") -> ScheduledModalModel:
    """The family carrying :func:`scheduled_simulation_covariance`, its ``meta["uncertainty_method"]`` saying how
    (without a covariance where the simulation is not finite)."""
    found = _simulation_fit(model, data, schedule, method)
    if found is None:
        return model.with_parameters(model.parameters, None)
    covariance, how = found
    return model.with_parameters(model.parameters, covariance, uncertainty_method=how.as_dict())


def _simulation_fit(model: ScheduledModalModel, data: IOData | Sequence[IOData], schedule: Any, method: str,
                    jackknife: bool = True, form: str = "linearised") -> Any:
    runs = Runs.of(data, schedule)
    base, jacobian = _simulation_jacobian(model, runs, method)
    theta = model.parameters
    residuals = base - runs.y
    if not (np.all(np.isfinite(jacobian)) and np.all(np.isfinite(residuals))):
        return None
    return fit_covariance(jacobian.reshape(-1, theta.size), residuals, dt=float(runs.records[0].dt),
                          jackknife=jackknife, form=form)


def _simulation_jacobian(model: ScheduledModalModel, runs: Runs, method: str,
                         central: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """The simulation from rest (N, n_y) and its Jacobian (N, n_y, n_theta) by central (or forward) differences,
    the runs' samples one after the other, each run simulated from rest.

    Steps of ``1e-6`` of each parameter, or of the largest of its kind where it is near zero. Forward
    differences halve the cost where the Jacobian only steers a step (:func:`refine_by_simulation`).
    """
    theta = model.parameters
    kinds = np.tile(_kinds(model.structure), model.grid.size)
    typical = {kind: float(np.max(np.abs(theta[kinds == kind]), initial=0.0)) for kind in set(kinds)}
    steps = _DIFFERENCE_STEP * np.maximum(np.abs(theta), np.array([max(typical[k], 1e-12) for k in kinds]))
    with np.errstate(all="ignore"):
        base = runs.simulate(model, method)
        jacobian = np.empty((*base.shape, theta.size))
        for i in range(theta.size):
            shifted = theta.copy()
            shifted[i] += steps[i]
            upper = runs.simulate(model.with_parameters(shifted), method)
            if not central:
                jacobian[:, :, i] = (upper - base) / steps[i]
                continue
            shifted[i] -= 2 * steps[i]
            lower = runs.simulate(model.with_parameters(shifted), method)
            jacobian[:, :, i] = (upper - lower) / (2 * steps[i])
    return base, jacobian


def refine_by_simulation(model: ScheduledModalModel, data: IOData | Sequence[IOData], schedule: Any, *,
                         method: str = "foh",
                         iterations: int = 15, stable: bool = True,
                         on_step: Callable[[ScheduledModalModel, int], None] | None = None
                         ) -> tuple[ScheduledModalModel, int]:
    """Levenberg-Marquardt steps on the family's simulation errors from rest, each output weighted by its spread.

    The filter minimises one-step prediction errors, which its measurement updates keep small even
    where a knot's coefficients simulate poorly; the family is judged (and returned or not) by its
    simulation. A step is taken only where it lowers the weighted sum of squares, keeps every knot
    stable (where asked) and the simulation finite; the damping grows until one does or the
    iterations end. Returns the family and the number of steps taken; ``on_step`` sees the family
    before the first step (0) and after each step taken (a caller may stop early on held-out data).
    Several records (``schedule`` then one array per record) are simulated each from rest.
    """
    runs = Runs.of(data, schedule)
    spread = np.std(runs.y, axis=0)
    spread = np.where(spread > 0, spread, 1.0)

    def cost(candidate: ScheduledModalModel) -> float:
        if stable and not candidate.is_stable():
            return np.inf
        with np.errstate(all="ignore"):
            error = (runs.simulate(candidate, method) - runs.y) / spread
        value = float(np.sum(error**2))
        return value if np.isfinite(value) else np.inf

    current = cost(model)
    if not np.isfinite(current):
        return model, 0
    if on_step is not None:
        on_step(model, 0)
    damping, taken = 1e-3, 0
    for _ in range(int(iterations)):
        base, jacobian = _simulation_jacobian(model, runs, method, central=False)
        if not (np.all(np.isfinite(base)) and np.all(np.isfinite(jacobian))):
            break
        J = (jacobian / spread[None, :, None]).reshape(-1, model.n_parameters)
        e = ((runs.y - base) / spread).ravel()
        normal, gradient = J.T @ J, J.T @ e
        scale = np.sqrt(np.maximum(np.diag(normal), 1e-300))
        normal_scaled = normal / np.outer(scale, scale)
        for _attempt in range(12):  # damping up by 10 until a step lowers the cost
            step = np.linalg.solve(normal_scaled + damping * np.eye(scale.size), gradient / scale) / scale
            candidate = model.with_parameters(model.parameters + step)
            trial = cost(candidate)
            if trial < current:
                model, current, taken = candidate, trial, taken + 1
                damping = max(damping / 10, 1e-9)
                if on_step is not None:
                    on_step(model, taken)
                break
            damping *= 10
        else:
            break
    return model, taken


def _growth_rates(structure: ModalStructure) -> np.ndarray:
    """Indices, within one knot, of each mode's sigma (its real part; the first of its modal parameters)."""
    sizes = [len(states) for states in structure.mode_states()]
    return np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(int)


def _kinds(structure: ModalStructure) -> np.ndarray:
    """The kind (0 modal, 1 B, 2 C, 3 D, 4 offset) of each parameter of one knot."""
    n, n_u, n_y = structure.n, structure.n_u, structure.n_y
    return np.concatenate([np.zeros(n, int), np.ones(n * (n_u - 1), int), np.full(n_y * n, 2), np.full(n_y * n_u, 3),
                           np.full(n_y, 4)])


def _knot_parameters(model: ModalModel, order: list[int] | None = None) -> np.ndarray:
    """One knot's parameters (input gauge, output offsets zero) of an unscheduled model, its modes in ``order``."""
    structure = model.structure
    A, B, C = input_gauge(model, list(range(len(structure.mode_states()))) if order is None else order)
    modal = np.array([A[s[0], s[0]] if k == 0 else abs(A[s[0], s[1]])
                      for s in structure.mode_states() for k in range(len(s))])
    return np.concatenate([gauge_parameters(modal, B, C, model.D), np.zeros(structure.n_y)])


def _mode_eigenvalues(model: ModalModel) -> np.ndarray:
    """One eigenvalue per mode of the structure, read from A's blocks: ``sigma + j|omega|``."""
    A = model.A
    return np.array([complex(A[s[0], s[0]], abs(A[s[0], s[1]]) if len(s) == 2 else 0.0)
                     for s in model.structure.mode_states()])


def _mode_order(reference: np.ndarray, candidate: np.ndarray, n_pairs: int) -> list[int]:
    """The candidate's modes in the reference's slots (pairs among pairs, real poles among real poles),
    least total relative eigenvalue distance."""
    from scipy.optimize import linear_sum_assignment  # slow to import: paid only where local starts are found

    order: list[int] = []
    for low, high in ((0, n_pairs), (n_pairs, reference.size)):
        if high <= low:
            continue
        cost = np.abs(reference[low:high, None] - candidate[None, low:high]) / np.maximum(
            np.abs(reference[low:high, None]), 1e-12)
        rows, columns = linear_sum_assignment(cost)
        order += [low + int(c) for c in columns[np.argsort(rows)]]
    return order


def knot_cells(schedule: np.ndarray, grid: np.ndarray) -> list[np.ndarray]:
    """Per knot, the indices of the samples whose schedule value lies nearer that knot than any other.

    The end knots take every sample beyond them, as the family holds their values there.
    """
    bounds = 0.5 * (grid[1:] + grid[:-1])
    cell = np.searchsorted(bounds, schedule)
    return [np.flatnonzero(cell == k) for k in range(grid.size)]


@dataclass(frozen=True)
class KnotCoverage:
    """How much of the record one knot of a scheduled family rests on (:func:`knot_coverage`).

    Attributes
    ----------
    value : float
        The knot (the schedule's value).
    samples : int
        Samples nearer this knot than any other (:func:`knot_cells`).
    seconds : float
        Their duration (s).
    excitation : float
        RMS of the first input over them, as a fraction of its RMS over the record.
    enough : bool
        Whether they say the knot's modes (module constants ``LOCAL_MIN_*``); where not, the knot's
        ordinates are extrapolated from its neighbours' data.
    """

    value: float
    samples: int
    seconds: float
    excitation: float
    enough: bool

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: ``value``, ``samples``, ``seconds``, ``excitation`` and ``extrapolated`` (not enough)."""
        return {"value": self.value, "samples": self.samples, "seconds": self.seconds,
                "excitation": self.excitation, "extrapolated": not self.enough}


def knot_coverage(data: IOData, schedule: np.ndarray, grid: np.ndarray, start: ModalModel) -> tuple[KnotCoverage, ...]:
    """Per knot, the samples it rests on and whether they are enough to say its modes.

    Enough: at least :data:`LOCAL_MIN_TIME_CONSTANTS` of the start's slowest mode and
    :data:`LOCAL_MIN_SAMPLES_PER_PARAMETER` per parameter of its structure, with the first input's RMS
    there at least :data:`LOCAL_MIN_EXCITATION` of the record's (a stretch driven straight says
    nothing); the same rule decides where a knot may start from its own local model.
    """
    structure = start.structure
    reference = _mode_eigenvalues(start)
    slowest = float(np.min(np.abs(reference))) if reference.size else 0.0
    needed = max(LOCAL_MIN_SAMPLES_PER_PARAMETER * structure.n_parameters,
                 int(np.ceil(LOCAL_MIN_TIME_CONSTANTS / max(slowest * data.dt, 1e-12))) if slowest > 0 else 0)
    record_rms = float(np.sqrt(np.mean(data.u[:, 0] ** 2)))
    coverage = []
    for value, rows in zip(grid, knot_cells(schedule, grid)):
        excitation = float(np.sqrt(np.mean(data.u[rows, 0] ** 2)) / record_rms) if rows.size and record_rms > 0 else 0.0
        coverage.append(KnotCoverage(float(value), int(rows.size), float(rows.size * data.dt), excitation,
                                     bool(rows.size >= needed and excitation >= LOCAL_MIN_EXCITATION)))
    return tuple(coverage)


def _local_model(data: IOData, rows: np.ndarray, start: ModalModel, input_scale: np.ndarray,
                 output_scale: np.ndarray, stable: bool, method: str) -> ModalModel | None:
    """The data start (:func:`~identification.filtering.start.data_start`) of one knot's samples, in seconds
    and the record's units, where it simulates those samples better than the whole record's start; else None.

    A knot's samples may come from several stretches of the record (a speed visited more than once); they
    are taken as one record, and both candidates are judged on the same joined samples from rest.
    """
    from .start import data_start

    structure = start.structure
    u, y = data.u[rows], data.y[rows]
    try:
        found = data_start(u / input_scale, y / output_scale, structure, method="data", stable=stable)
    except (WorkbenchError, np.linalg.LinAlgError):
        return None
    theta = structure.denormalize(structure.rescale_time(found.model.parameters, 1.0 / data.dt), input_scale,
                                  output_scale)
    local = ModalModel.from_parameters(structure, theta)
    if stable and not local.is_stable():
        return None

    return local if _cell_fit(local, data, rows, method) > _cell_fit(start, data, rows, method) else None


def _cell_fit(model: ModalModel, data: IOData, rows: np.ndarray, method: str) -> float:
    """Mean R (eq. 17) of an unscheduled model simulated from rest on some samples of a record, joined."""
    with np.errstate(all="ignore"):
        simulated = model.simulate_outputs(data.u[rows], data.dt, method=method)
    if not np.all(np.isfinite(simulated)):
        return -np.inf
    return float(np.mean(percentage_explanation(data.y[rows], simulated)))


def _local_start_family(family: ScheduledModalModel, start: ModalModel, data: IOData, schedule: np.ndarray,
                        input_scale: np.ndarray, output_scale: np.ndarray, stable: bool, method: str,
                        runs: Runs | None = None) -> tuple[ScheduledModalModel, list[str]] | None:
    """The family started knot by knot from models of the samples near each knot, or None where that
    does not simulate the record better than ``family`` (the whole record's start at every knot). ``data``
    and ``schedule`` hold every sample (of all ``runs``, one after the other, where there are several).

    Each knot takes its local model (:func:`_local_model`) where its samples are enough
    (:data:`LOCAL_MIN_TIME_CONSTANTS` of the start's slowest mode and :data:`LOCAL_MIN_SAMPLES_PER_PARAMETER`
    per parameter), excited (the first input's RMS there at least :data:`LOCAL_MIN_EXCITATION` of the
    record's) and simulated better by it than by the whole record's start; else the local model of its
    nearest knot on either side that simulates its samples better. Local modes take the start's order by
    least eigenvalue distance, so that the same slot means the same mode at every knot.
    """
    structure = start.structure
    size = knot_size(structure)
    reference = _mode_eigenvalues(start)
    cells = knot_cells(schedule, family.grid)
    local: dict[int, ModalModel] = {}
    for k, (rows, covered) in enumerate(zip(cells, knot_coverage(data, schedule, family.grid, start))):
        if covered.enough:
            model = _local_model(data, rows, start, input_scale, output_scale, stable, method)
            if model is not None:
                local[k] = model
    if not local:
        return None
    # A knot without a local model of its own takes its nearest neighbours' that simulates its samples
    # better, never the whole record's start: that start is often near a double pole, whose residues are
    # large and cancel, and interpolated against a local model's they no longer cancel (on a speed ramp
    # the lateral acceleration's fit fell from 75 % to below -200 %).
    theta = family.parameters.copy()
    labels = []
    for k, rows in enumerate(cells):
        if k in local:
            chosen, label = k, "local"
        else:
            below = [j for j in local if j < k]
            above = [j for j in local if j > k]
            nearest = ([max(below)] if below else []) + ([min(above)] if above else [])
            chosen = max(nearest, key=lambda j: _cell_fit(local[j], data, rows, method)) if rows.size else nearest[0]
            label = f"local of knot {chosen}"
        order = _mode_order(reference, _mode_eigenvalues(local[chosen]), structure.n_complex_pairs)
        try:
            theta[k * size:(k + 1) * size] = _knot_parameters(local[chosen], order)
        except InputError:  # a local mode not driven by the first input has no gauge
            return None
        labels.append(label)
    candidate = family.with_parameters(theta)

    def mean_fit(model: ScheduledModalModel) -> float:
        if stable and not model.is_stable():
            return -np.inf
        with np.errstate(all="ignore"):
            simulated = (runs or Runs.of(data, schedule)).simulate(model, method)
        return float(np.mean(percentage_explanation(data.y, simulated))) if np.all(np.isfinite(simulated)) else -np.inf

    return (candidate, labels) if mean_fit(candidate) > mean_fit(family) else None


@on_one_blas_thread
def identify_scheduled(
    data: IOData,
    schedule: Any,
    start: ModalModel,
    *,
    variable: str = "schedule",
    options: ScheduledIEKFOptions | None = None,
    on_pass: Callable[[PassRecord, ScheduledIEKFResult], None] | None = None,
    on_refine: Callable[[ScheduledModalModel, int], None] | None = None,
) -> ScheduledIEKFResult:
    """Identify a scheduled modal family from a record (or several) along its measured schedule.

    Parameters
    ----------
    data : IOData or sequence of IOData
        The record: inputs and outputs (offsets removed), without the schedule. Several records (the
        runs of a drive between stops) are passed over in turn, each from rest, as the linear filter's.
    schedule : array_like (N,), or one per record
        The scheduling channel at each sample, in its own units (a speed in m/s).
    start : ModalModel
        An unscheduled model of the same record (its structure fixes the modes); every mode must be
        driven by the first input. The start at every knot, unless local starts
        (:attr:`ScheduledIEKFOptions.local_starts`) simulate the record better; ``meta["local_starts"]``
        of the result says which knot started from what (empty where none did).
    variable : str
        The schedule's name (the channel), kept with the family.
    options : ScheduledIEKFOptions, optional
        Settings; :class:`ScheduledIEKFOptions`' defaults without them.
    on_pass : callable, optional
        Called after every pass with its record and the result so far.
    on_refine : callable, optional
        Called with the family and the step count before and after each refinement step
        (:func:`refine_by_simulation`).

    Returns
    -------
    ScheduledIEKFResult
        The identified family, its start and one record per pass.

    Raises
    ------
    InputError
        On a schedule of the wrong length or that barely varies, or data not matching ``start``.
    DivergenceError
        Non-finite filter values or a family whose simulation blows up;
        ``last_good`` holds the result of the last good pass (None before the first).
    """
    options = options or ScheduledIEKFOptions()
    structure = start.structure
    runs = Runs.of(data, schedule)
    data, schedule = runs.joined, runs.schedule  # every sample, the runs one after the other (knots, local starts)
    grid = check_grid(options.grid) if options.grid is not None else default_grid(schedule, options.knots)
    count = grid.size
    filter_model = ScheduledFilterModel(structure, count)
    check_records(runs.records, structure.n_u, structure.n_y, filter_model.n_theta, "the start model")
    started = time.perf_counter()
    dt = data.dt
    method = HOLD_OF[options.discretization]

    input_scale, output_scale = signal_scales(data, True)
    knot_theta = _knot_parameters(start)
    coverage = [covered.as_dict() for covered in knot_coverage(data, schedule, grid, start)]
    family = ScheduledModalModel.from_parameters(
        structure, grid, np.tile(knot_theta, count), variable=variable, input_names=start.input_names,
        output_names=start.output_names, meta={"estimator": "scheduled-iekf", "dt": dt, "knot_coverage": coverage})
    start_theta = np.tile(knot_theta, count)
    record_family = family  # the given start at every knot, a candidate for the refinement whatever the start
    local_starts: list[str] = []
    if options.local_starts:
        local = _local_start_family(family, start, data, schedule, input_scale, output_scale, options.stable, method,
                                    runs)
        if local is not None:
            family, local_starts = local
            start_theta = family.parameters
    scale = np.tile(_unit_scale(structure, input_scale, output_scale, dt), count)
    rates = np.abs(start.mode_eigenvalues())
    # the start's dominant time constant, as the linear filter takes it (rates clipped to the band a record shows)
    time_constant = float(1.0 / np.median(np.clip(rates, 1e-6 / dt, (np.pi / 4) / dt)))
    ratio = dt / time_constant
    weights = np.tile(_time_weights(structure, ratio), count)
    n = structure.n
    q_first = np.concatenate([np.zeros(n), weights**2 * ratio * options.p])
    q = q_first.copy()
    P0 = np.diag(np.concatenate([np.zeros(n), weights**2 * options.p]))
    r = np.diag(data_measurement_noise(runs.records) / output_scale**2)
    u_filters = [np.column_stack([record.u / input_scale, s]) for record, s in zip(runs.records, runs.schedules)]
    y_filters = [record.y / output_scale for record in runs.records]
    run_pass = compiled_pass(filter_model, 1.0, options.discretization, options.covariance,
                             expected_steps=options.passes * data.n_samples)

    def simulate(candidate: ScheduledModalModel) -> np.ndarray:
        with np.errstate(all="ignore"):
            return runs.simulate(candidate, method)

    start_fit = percentage_explanation(data.y, simulate(family))
    start_family = family

    def prepare_pass(index: int) -> None:
        shrink = max(options.p_decay ** (index - 1), P_DECAY_FLOOR) if options.p_decay < 1 else 1.0
        q[:] = q_first * shrink

    growth = (_growth_rates(structure)[None, :] + knot_size(structure) * np.arange(count)[:, None]).ravel()

    def assess(theta: np.ndarray, P: np.ndarray) -> Assessment:
        if options.stable and np.any(theta[growth] > 0):
            # reflect: a linear change of the parameters, so P follows with the same sign flips
            flip = np.ones(P.shape[0])
            flip[n + growth[theta[growth] > 0]] = -1.0
            theta = theta * flip[n:]
            P = P * np.outer(flip, flip)
        candidate = family.with_parameters(theta * scale)
        y_hat = simulate(candidate)
        if not (np.all(np.isfinite(y_hat)) and np.max(np.abs(y_hat)) < 1e6 * max(np.max(np.abs(data.y)), 1e-300)):
            raise DivergenceError("the scheduled model's simulation blows up (try a lower p)")
        fit = percentage_explanation(data.y, y_hat)
        return Assessment(candidate.parameters, fit, fit, theta, P)

    def result(stop_reason: str, history: tuple[PassRecord, ...], theta: np.ndarray, P: np.ndarray
               ) -> ScheduledIEKFResult:
        final = family.with_parameters(theta * scale, passes=len(history), stop_reason=stop_reason)
        refined: dict[str, Any] = {}
        if stop_reason != "running" and history and options.refine_iterations:
            # from whichever of the filter's family, its start and (where the knots started locally) the
            # given start at every knot simulates better: the local start is a better place for the
            # filter to begin, not always for the simulation errors to end
            simulated = {name: percentage_explanation(data.y, simulate(candidate))
                         for name, candidate in (("filter", final), ("start", start_family),
                                                 ("record start", record_family))
                         if name != "record start" or candidate is not start_family}
            origin = max(simulated, key=lambda name: float(np.nan_to_num(np.mean(simulated[name]), nan=-np.inf)))
            chosen = {"filter": final, "start": start_family, "record start": record_family}[origin]
            base = final if origin == "filter" else chosen.with_parameters(
                chosen.parameters, passes=len(history), stop_reason=stop_reason)
            final, steps = refine_by_simulation(base, runs.records, runs.schedules, method=method,
                                                iterations=options.refine_iterations, stable=options.stable,
                                                on_step=on_refine)
            # either start is "start" to a caller (how far the passes got does not matter); which one, apart
            refined = {"refined_from": "filter" if origin == "filter" else "start",
                       "refined_start": None if origin == "filter" else
                       ("record" if chosen is record_family else "local"), "refine_steps": steps,
                       "fit_percent": percentage_explanation(data.y, simulate(final))}
        if stop_reason != "running" and history:
            final = with_simulation_covariance(final, runs.records, runs.schedules, method)
        return ScheduledIEKFResult(final, start_family, options, history, P.copy(), start_fit, stop_reason,
                                   time.perf_counter() - started, {"grid": grid, "time_constant": time_constant,
                                                                    "local_starts": tuple(local_starts), **refined})

    hooks = RinseHooks(
        runs.records, lambda state, k: run_pass(state, u_filters[k], y_filters[k], q, r, grid), lambda: r, assess,
        lambda previous, current: abs(current.mean_fit_filter - previous.mean_fit_filter) < options.fit_tolerance,
        result, n, label="scheduled pass", prepare_pass=prepare_pass,
    )
    return rinse(hooks, start_theta / scale, P0, passes=options.passes, min_passes=options.min_passes,
                 on_pass=on_pass)
