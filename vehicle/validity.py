"""Where the vehicle model is valid: speed range, physical envelope, step size and memory.

A simulation that leaves the range in which its equations describe a car must
say so rather than return numbers. Three kinds of check, each with its limits
stated here once (and in ``docs/conventions.md``):

* Up front, on the input (:class:`~identification.errors.InputError`, exit
  status 2): the speed range (:data:`MIN_SPEED`, :data:`MAX_SPEED`, or
  :data:`MAX_SPEED_AERO` for a vehicle with aerodynamic drag), the RK4
  step against the fastest modes at trim (:func:`check_rk4_step`), and the
  memory a record will take (:func:`check_memory`). The vehicle's own static
  stability is checked when its parameters are built
  (:mod:`vehid.vehicle.parameters`).
* During the run, on the states (:data:`ENVELOPE`, :func:`first_violation`):
  roll, pitch, sideslip, lateral and longitudinal tyre slip, departure from the
  reference speed, heave, and non-finite or exploding values. The simulator
  stops at the first sample outside and raises
  :class:`~identification.errors.SimulationError` (exit status 1) with the
  record up to that sample.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from vehid.identification.errors import InputError

__all__ = [
    "MIN_SPEED",
    "MAX_SPEED",
    "MAX_SPEED_AERO",
    "MEMORY_FRACTION",
    "EnvelopeLimit",
    "ENVELOPE",
    "Violation",
    "first_violation",
    "check_speed_range",
    "rk4_amplification",
    "largest_stable_step",
    "check_rk4_step",
    "available_memory_bytes",
    "check_memory",
]

# Below MIN_SPEED the tyre model leaves its range: the smoothed |V_cx| of the slip
# lags (eps = 0.1 m/s) biases slip by eps^2 / (2 V^2) (0.06 % at 3 m/s, 50 % at
# 0.1 m/s, where the car slides sideways at 90 deg of sideslip), and the lags'
# damping falls in proportion to speed: the 30 Hz wheel-spin / longitudinal-lag
# modes have damping 0.35 at 20 m/s, 0.05 at 3 m/s and 0.035 at 2 m/s, so below
# about 3 m/s they ring for seconds - the standstill problem of first-order
# transient slip (Pacejka 2012, section 8.6), for which this model carries no
# low-speed damping. MF-Tyre's own low-speed threshold (VXLOW) is 1 m/s.
MIN_SPEED = 3.0  # [m/s]
# Above MAX_SPEED what the model leaves out is no longer small: aerodynamic drag
# (C_d A about 0.7 m^2: 1.1 kN, 7 % of the weight at 50 m/s) and lift (axle load
# changes of several per cent), and the PI speed hold is tuned at 20 m/s.
MAX_SPEED = 50.0  # [m/s], 180 km/h
# A vehicle with aerodynamic drag and downforce (vehicle.parameters.AeroParameters) has what the
# limit above is about; its range reaches track speeds. Beyond them the PI speed hold, tuned at
# 20 m/s, and the slip lags' RK4 step (sized at the top speed of a record) are the limits.
MAX_SPEED_AERO = 75.0  # [m/s], 270 km/h
# A record's arrays may take at most this share of the memory available when it starts.
MEMORY_FRACTION = 0.5
_PEAK_COPIES = 3  # the integrator's arrays, their stacked copy and the record's own copy


@dataclass(frozen=True)
class EnvelopeLimit:
    """One bound of the physical envelope: ``|quantity| <= limit`` (SI units)."""

    quantity: str
    limit: float
    unit: str  # the unit it is reported in ("" for a ratio)
    scale: float  # SI value times scale = reported value
    reason: str


_DEG = math.pi / 180.0

ENVELOPE: tuple[EnvelopeLimit, ...] = (
    EnvelopeLimit("roll angle", 15 * _DEG, "deg", 1 / _DEG,
                  "a road car rolls 3-7 deg at its grip limit (this one 4 deg at 0.79 g); beyond 15 deg "
                  "the suspension would be on its bump stops, which the linear struts do not have"),
    EnvelopeLimit("pitch angle", 10 * _DEG, "deg", 1 / _DEG,
                  "hard braking pitches a saloon 2-4 deg; beyond 10 deg the struts are past their travel"),
    EnvelopeLimit("sideslip", 15 * _DEG, "deg", 1 / _DEG,
                  "the car is spinning: a road car at its grip limit slips 2-6 deg at the CG"),
    EnvelopeLimit("lateral tyre slip", 20 * _DEG, "deg", 1 / _DEG,
                  "beyond the slip angles at which tyre data are measured (about +/-20 deg); "
                  "this tyre's force peaks near 10 deg"),
    EnvelopeLimit("longitudinal tyre slip", 0.5, "", 1.0,
                  "the wheel spins up or locks: the drive force peaks near a slip ratio of 0.1"),
    EnvelopeLimit("speed departure", 0.2, "of the reference speed", 1.0,
                  "the PI speed hold keeps within 0.5 % in normal driving; 20 % means it has lost traction"),
    EnvelopeLimit("heave", 0.15, "m", 1.0,
                  "a saloon's bump and rebound travel is about 0.1 m each way"),
    EnvelopeLimit("state magnitude", 1e6, "SI units", 1.0, "the integration is exploding"),
)
_LIMITS = {limit.quantity: limit for limit in ENVELOPE}


@dataclass(frozen=True)
class Violation:
    """The first sample at which a record leaves the envelope."""

    quantity: str
    value: float  # SI units (a fraction for the speed departure)
    sample: int
    limit: EnvelopeLimit | None  # None for a non-finite value
    column: str  # the state or output that carries it

    def message(self, t0: float, dt: float) -> str:
        time = t0 + self.sample * dt
        if self.limit is None:
            return (f"the vehicle simulation produced a non-finite value ({self.column} = {self.value}) "
                    f"at t = {time:.3f} s")
        unit = f" {self.limit.unit}" if self.limit.unit else ""
        shown, bound = self.value * self.limit.scale, self.limit.limit * self.limit.scale
        corner = _WHEELS.get(self.column.rpartition("_")[2], "") if "_" in self.column else ""
        where = f"{self.column}, the {corner} wheel" if corner else self.column
        return (f"the vehicle left its valid envelope at t = {time:.3f} s: {self.quantity} "
                f"{shown:.4g}{unit} ({where}) beyond +/-{bound:.4g}{unit} ({self.limit.reason})")


_WHEELS = {"fl": "front-left", "fr": "front-right", "rl": "rear-left", "rr": "rear-right"}


def _columns(names: Sequence[str], wanted: Sequence[str]) -> list[int]:
    return [list(names).index(name) for name in wanted]


def first_violation(
    states: np.ndarray,
    state_names: Sequence[str],
    outputs: np.ndarray,
    output_names: Sequence[str],
    reference_speed: float | np.ndarray,
    *,
    state_offset: int = 0,
    output_offset: int = 0,
) -> Violation | None:
    """The earliest sample of a block at which the vehicle leaves :data:`ENVELOPE`, or None.

    Parameters
    ----------
    states : ndarray (n, 23)
        States of samples ``state_offset ... state_offset + n - 1``.
    outputs : ndarray (m, 10)
        Outputs of samples ``output_offset ... output_offset + m - 1`` (the
        simulator computes each output one step behind its state).
    reference_speed : float or ndarray (m,)
        The speed hold's target (m/s): one value, or one per output sample of a speed profile.

    Vectorised over the block: a few array operations per call, none per sample.
    """
    corners = ("fl", "fr", "rl", "rr")
    reference = np.asarray(reference_speed, dtype=float)
    if reference.ndim:  # a profile: one target per output row
        reference = reference.reshape(-1, 1)
    checks = [
        ("roll angle", states, state_offset, _columns(state_names, ["phi"]), 0.0, 1.0),
        ("pitch angle", states, state_offset, _columns(state_names, ["theta"]), 0.0, 1.0),
        ("sideslip", outputs, output_offset, _columns(output_names, ["sideslip"]), 0.0, 1.0),
        ("lateral tyre slip", states, state_offset,
         _columns(state_names, [f"alpha_{c}" for c in corners]), 0.0, 1.0),
        ("longitudinal tyre slip", states, state_offset,
         _columns(state_names, [f"kappa_{c}" for c in corners]), 0.0, 1.0),
        ("speed departure", outputs, output_offset, _columns(output_names, ["speed"]),
         reference, 1.0 / reference),
        ("heave", states, state_offset, _columns(state_names, ["z"]), 0.0, 1.0),
        # psi grows without bound while the car turns: it is ignorable and left out
        ("state magnitude", states, state_offset,
         [i for i, name in enumerate(state_names) if name != "psi"], 0.0, 1.0),
    ]
    found: list[tuple[int, int, Violation]] = []
    for priority, (array, offset, names) in enumerate(((states, state_offset, state_names),
                                                        (outputs, output_offset, output_names))):
        finite = np.isfinite(array)
        if not finite.all():
            row = int(np.argmin(finite.all(axis=1)))
            column = int(np.argmin(finite[row]))
            found.append((offset + row, -2 + priority, Violation(
                "non-finite value", float(array[row, column]), offset + row, None, names[column])))
    for priority, (quantity, array, offset, columns, centre, scale) in enumerate(checks):
        if array.shape[0] == 0:
            continue
        values = np.abs(array[:, columns] - centre) * scale
        outside = values > _LIMITS[quantity].limit  # NaN compares False: reported as non-finite above
        rows = outside.any(axis=1)
        if rows.any():
            row = int(np.argmax(rows))
            column = int(np.argmax(np.where(np.isfinite(values[row]), values[row], -np.inf)))
            names = state_names if array is states else output_names
            # a speed profile's centre and scale are one per row
            row_centre = centre[row, 0] if np.ndim(centre) else centre
            row_scale = scale[row, 0] if np.ndim(scale) else scale
            signed = float((array[row, columns[column]] - row_centre) * row_scale)
            found.append((offset + row, priority, Violation(
                quantity, signed, offset + row, _LIMITS[quantity], names[columns[column]])))
    if not found:
        return None
    return min(found, key=lambda item: item[:2])[2]


def check_speed_range(speed: float, maximum: float = MAX_SPEED) -> float:
    """Return ``speed`` if it lies in the model's valid range, else raise InputError with the reason.

    ``maximum`` is :data:`MAX_SPEED`, or :data:`MAX_SPEED_AERO` for a vehicle with aerodynamic forces.
    """
    if speed < MIN_SPEED:
        raise InputError(
            f"speed {speed:g} m/s is below the model's valid range ({MIN_SPEED:g}-{maximum:g} m/s): "
            "the tyre's slip lags lose their damping and the smoothed slip its accuracy at low speed"
        )
    if speed > maximum:
        reason = ("the model has no aerodynamic drag or lift, which are no longer small there"
                  if maximum <= MAX_SPEED else "the PI speed hold and the tyre data are not meant for it")
        raise InputError(
            f"speed {speed:g} m/s is above the model's valid range ({MIN_SPEED:g}-{maximum:g} m/s): {reason}"
        )
    return speed


def rk4_amplification(z: np.ndarray) -> np.ndarray:
    """|R(z)| of the classical Runge-Kutta method, ``R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24``."""
    z = np.asarray(z, dtype=complex)
    return np.abs(1 + z * (1 + z / 2 * (1 + z / 3 * (1 + z / 4))))


def largest_stable_step(eigenvalues: np.ndarray, upper: float) -> float:
    """The largest step up to ``upper`` at which RK4 keeps every mode ``eigenvalues`` stable (bisection)."""
    eigenvalues = np.asarray(eigenvalues)[np.abs(np.asarray(eigenvalues)) > 0]
    low, high = 0.0, float(upper)
    if eigenvalues.size == 0 or np.all(rk4_amplification(eigenvalues * high) <= 1.0 + 1e-9):
        return high
    for _ in range(60):
        middle = 0.5 * (low + high)
        if np.all(rk4_amplification(eigenvalues * middle) <= 1.0 + 1e-9):
            low = middle
        else:
            high = middle
    return low


def check_rk4_step(eigenvalues: np.ndarray, dt: float, speed: float) -> None:
    """Raise InputError if one RK4 step of ``dt`` per sample is unstable for a mode at trim.

    ``eigenvalues`` are those of the model linearised at the trim the record
    starts from. A step outside RK4's stability region makes the record grow
    without bound (at 100 Hz, to 1e49 within seconds at 60 m/s), so it is
    refused before any work, naming the step that would do.
    """
    eigenvalues = np.asarray(eigenvalues)
    growth = rk4_amplification(eigenvalues * dt)
    if np.all(growth <= 1.0 + 1e-9):
        return
    worst = eigenvalues[int(np.argmax(growth))]
    stable = largest_stable_step(eigenvalues, dt)
    raise InputError(
        f"dt = {dt:g} s is too long for the RK4 simulator at {speed:g} m/s: the mode at "
        f"{worst.real:.1f}{worst.imag:+.1f}j 1/s ({abs(worst) / (2 * math.pi):.1f} Hz) grows by "
        f"{float(np.max(growth)):.3g} per step; use dt <= {stable:.4g} s"
    )


def available_memory_bytes() -> int | None:
    """Memory the operating system can give without swapping (bytes), or None if it does not say."""
    try:
        with open("/proc/meminfo", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (OSError, ValueError, AttributeError):
        return None


def check_memory(n_samples: int, columns: int) -> int:
    """Refuse, before any work, a record whose arrays would not fit in memory; return its estimate.

    The estimate is ``n_samples * columns * 8`` bytes per copy, times the
    copies alive at the peak (the integrator's arrays, their stacked copy and
    the record's own copy, three). It must stay within
    :data:`MEMORY_FRACTION` of the memory available now.
    """
    estimate = int(n_samples) * int(columns) * 8 * _PEAK_COPIES
    available = available_memory_bytes()
    if available is not None and estimate > MEMORY_FRACTION * available:
        raise InputError(
            f"a record of {n_samples:,} samples needs about {estimate / 2**30:.3g} GiB at its peak, more than "
            f"{MEMORY_FRACTION:.0%} of the {available / 2**30:.3g} GiB of memory available: "
            "shorten the record or lengthen dt"
        )
    return estimate
