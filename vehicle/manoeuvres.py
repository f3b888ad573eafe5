"""Steer inputs: seeded road-wheel steer series for identification, validation and handling tests.

Every manoeuvre is a function with the same keyword-only signature
``(amplitude=None, duration=None, dt=1/500, seed=0)`` returning a frozen
:class:`Manoeuvre` whose ``steer`` (rad, shape (N,)) starts at zero, so that a
simulation starts at the straight-running trim. Amplitudes are road-wheel
angles in radians; the defaults are sized for the baseline saloon at 20 m/s.

Most manoeuvres run at the constant speed the simulation is given. Those
named ``speed-*`` carry their own reference speed (``Manoeuvre.speed``, m/s,
one value per sample), which the car's speed hold tracks: a ramp from 10 to
35 m/s and an accelerate-brake cycle, both under random steer within the
linear range, so that records of varying speed exist for speed-scheduled
identification. :func:`with_speed_profile` gives any steer series a profile.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Callable, Mapping

import numpy as np

from vehid.identification.errors import InputError

from .choices import MANOEUVRE_NAMES
from .simulation import DEFAULT_DT, check_record_memory, check_speed_profile, check_steer

__all__ = [
    "Manoeuvre",
    "identification",
    "validation",
    "step",
    "sweep",
    "ramp",
    "speed_ramp",
    "speed_cycle",
    "with_speed_profile",
    "MANOEUVRES",
    "make_manoeuvre",
    "band_limited_noise",
    "speed_from_accelerations",
]

_DEG = math.pi / 180.0


@dataclass(frozen=True, eq=False)
class Manoeuvre:
    """A named steer series.

    Attributes
    ----------
    name : str
        The manoeuvre's name (a key of :data:`MANOEUVRES`).
    steer : numpy.ndarray, shape (N,)
        Road-wheel steer angle (rad), positive left; ``steer[0] == 0``.
    dt : float
        Sample interval (s).
    meta : mapping
        How it was made: amplitude (rad), duration (s), seed, and shape details.
    speed : numpy.ndarray, shape (N,), optional
        Reference speed (m/s) per sample for the speed hold to track; None
        where the simulation's constant speed applies.
    """

    name: str
    steer: np.ndarray
    dt: float
    meta: Mapping[str, Any] = field(default_factory=dict)
    speed: np.ndarray | None = None

    def __post_init__(self) -> None:
        steer = check_steer(self.steer).copy()
        steer.setflags(write=False)
        object.__setattr__(self, "steer", steer)
        if self.speed is not None:
            speed = check_speed_profile(self.speed, steer.size).copy()
            speed.setflags(write=False)
            object.__setattr__(self, "speed", speed)
        object.__setattr__(self, "meta", MappingProxyType({"manoeuvre": self.name, **dict(self.meta)}))

    @property
    def t(self) -> np.ndarray:
        """Sample times (s), shape (N,)."""
        return self.dt * np.arange(self.steer.size)

    @property
    def n_samples(self) -> int:
        """Number of samples N."""
        return int(self.steer.size)

    def __array__(self, dtype=None, copy=None):
        return np.array(self.steer, dtype=dtype)


def _samples(duration: float, dt: float) -> int:
    for name, value in (("duration", duration), ("dt", dt)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise InputError(f"manoeuvre {name} must be a positive number of seconds; got {value!r}")
    n = int(round(duration / dt)) + 1
    if n < 2:
        raise InputError(f"duration {duration} s holds fewer than 2 samples at dt = {dt} s")
    check_record_memory(n)  # a manoeuvre is made to be simulated: refuse one too long before building it
    return n


def _check_amplitude(amplitude: float) -> float:
    if not (isinstance(amplitude, (int, float)) and math.isfinite(amplitude)):
        raise InputError(f"manoeuvre amplitude must be a finite angle (rad); got {amplitude!r}")
    return float(amplitude)


def _check_seed(seed: int) -> int:
    """The seed as an int, or InputError: NumPy's generators take non-negative integers only."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"manoeuvre seed must be a non-negative integer; got {seed!r}")
    return int(seed)


def _fade(t: np.ndarray, rise: float) -> np.ndarray:
    """Raised-cosine fade-in over ``rise`` seconds: 0 at t = 0, 1 after."""
    x = np.clip(t / rise, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * x)


def _chirp(t: np.ndarray, f0: float, f1: float, duration: float) -> np.ndarray:
    """Linear sine sweep from f0 to f1 Hz over ``duration`` s."""
    return np.sin(2 * np.pi * (f0 * t + 0.5 * (f1 - f0) / duration * t**2))


def _smoothed_step(t: np.ndarray, start: float, ramp_time: float) -> np.ndarray:
    """0 before ``start``, a linear ramp over ``ramp_time`` s, 1 after."""
    return np.clip((t - start) / ramp_time, 0.0, 1.0)


def band_limited_noise(n: int, dt: float, bandwidth: float, rng: np.random.Generator) -> np.ndarray:
    """Gaussian white noise limited to ``0..bandwidth`` Hz (ideal FFT filter), unit RMS, shape (n,)."""
    white = rng.standard_normal(n)
    spectrum = np.fft.rfft(white)
    spectrum[np.fft.rfftfreq(n, dt) > bandwidth] = 0.0
    noise = np.fft.irfft(spectrum, n)
    noise -= noise.mean()
    return noise / np.sqrt(np.mean(noise**2))


def identification(
    *, amplitude: float | None = None, duration: float | None = None, dt: float = DEFAULT_DT, seed: int = 0
) -> Manoeuvre:
    """The paper's identification input: band-limited noise plus a sinusoidal sweep.

    Band-limited white noise (0-25 Hz, RMS ``0.15 * amplitude``) plus a linear
    sine sweep of ``amplitude`` from 0.1 to 2 Hz over the record, both faded in
    over the first second (Best & Bogdanski, section 6). The default amplitude
    (4 deg road-wheel) takes the baseline saloon at 20 m/s to about
    +/-7 m/s^2 lateral acceleration, some 90 % of its grip limit (0.79 g); the
    peak comes early in the sweep, where the frequency is lowest.
    """
    amplitude = _check_amplitude(4.0 * _DEG if amplitude is None else amplitude)
    seed = _check_seed(seed)
    duration = 30.0 if duration is None else duration
    n = _samples(duration, dt)
    t = dt * np.arange(n)
    rng = np.random.default_rng(seed)
    noise = band_limited_noise(n, dt, 25.0, rng)
    steer = amplitude * _fade(t, 1.0) * (_chirp(t, 0.1, 2.0, duration) + 0.15 * noise)
    return Manoeuvre(
        "identification", steer, dt,
        {"amplitude": amplitude, "duration": duration, "seed": seed,
         "sweep_hz": [0.1, 2.0], "noise_band_hz": [0.0, 25.0], "noise_rms_fraction": 0.15},
    )


def validation(
    *, amplitude: float | None = None, duration: float | None = None, dt: float = DEFAULT_DT, seed: int = 0
) -> Manoeuvre:
    """The paper's validation input: steps added to a sweep, then a range of larger steps.

    First half: a slow sweep (0.1-0.6 Hz) of ``0.6 * amplitude`` with steps of
    ``+/-0.4 * amplitude`` added every 1.5 s, together spanning the nonlinear
    range. Second half: steps of 0.5, 0.7, 0.9, 1.1 and 1.3 times
    ``amplitude``, alternating in sign, each held then released. Step edges
    ramp over 0.1 s. The step order is drawn from ``seed``. The default
    amplitude is 3.5 deg: for the baseline saloon at 20 m/s the first half
    peaks near 6.3 m/s^2, and the largest step (4.55 deg) settles near
    7.1 m/s^2 (0.72 g) after an overshoot to about 7.5 m/s^2, close to but
    short of the 0.79 g grip limit.
    """
    amplitude = _check_amplitude(3.5 * _DEG if amplitude is None else amplitude)
    seed = _check_seed(seed)
    duration = 30.0 if duration is None else duration
    n = _samples(duration, dt)
    t = dt * np.arange(n)
    half = duration / 2
    rng = np.random.default_rng(seed)
    first = t < half
    sweep_part = 0.6 * _chirp(t, 0.1, 0.6, half) * _fade(t, 1.0)
    steps = np.zeros(n)
    edges = np.arange(1.5, half - 1.0, 1.5)
    levels = rng.choice([-0.4, 0.4], size=edges.size)
    previous = 0.0
    for edge, level in zip(edges, levels):
        steps += (level - previous) * _smoothed_step(t, edge, 0.1)
        previous = level
    steps -= previous * _smoothed_step(t, half - 1.0, 0.1)
    signal = np.where(first, sweep_part * _fade(half - t, 1.0) + steps, 0.0)
    magnitudes = np.array([0.5, 0.7, 0.9, 1.1, 1.3])
    signs = np.resize([1.0, -1.0], magnitudes.size) * rng.choice([-1.0, 1.0])
    slot = (duration - half) / magnitudes.size
    for i, (magnitude, sign) in enumerate(zip(magnitudes, signs)):
        on = half + i * slot + 0.2 * slot
        off = on + 0.5 * slot
        signal += sign * magnitude * (_smoothed_step(t, on, 0.1) - _smoothed_step(t, off, 0.1))
    return Manoeuvre(
        "validation", amplitude * signal, dt,
        {"amplitude": amplitude, "duration": duration, "seed": seed,
         "step_magnitudes": magnitudes.tolist()},
    )


def step(
    *, amplitude: float | None = None, duration: float | None = None, dt: float = DEFAULT_DT, seed: int = 0
) -> Manoeuvre:
    """ISO 7401-style step steer: zero for 0.5 s, a 0.1 s ramp to ``amplitude``, then held.

    Default 1 deg road-wheel over 5 s (long enough for the PI speed hold to
    settle, so the end of the record is the steady state).
    """
    amplitude = _check_amplitude(1.0 * _DEG if amplitude is None else amplitude)
    seed = _check_seed(seed)
    duration = 5.0 if duration is None else duration
    n = _samples(duration, dt)
    t = dt * np.arange(n)
    start, ramp_time = 0.5, 0.1
    steer = amplitude * _smoothed_step(t, min(start, duration / 4), ramp_time)
    return Manoeuvre(
        "step", steer, dt,
        {"amplitude": amplitude, "duration": duration, "seed": seed, "start": start, "ramp_time": ramp_time},
    )


def sweep(
    *, amplitude: float | None = None, duration: float | None = None, dt: float = DEFAULT_DT, seed: int = 0
) -> Manoeuvre:
    """Sine sweep (chirp) from 0.1 to 3 Hz at ``amplitude`` (default 1 deg), faded in over 1 s."""
    amplitude = _check_amplitude(1.0 * _DEG if amplitude is None else amplitude)
    seed = _check_seed(seed)
    duration = 30.0 if duration is None else duration
    n = _samples(duration, dt)
    t = dt * np.arange(n)
    steer = amplitude * _fade(t, 1.0) * _chirp(t, 0.1, 3.0, duration)
    return Manoeuvre("sweep", steer, dt, {"amplitude": amplitude, "duration": duration, "seed": seed,
                                          "sweep_hz": [0.1, 3.0]})


def ramp(
    *, amplitude: float | None = None, duration: float | None = None, dt: float = DEFAULT_DT, seed: int = 0
) -> Manoeuvre:
    """Slow ramp steer for the handling curve: 0 to ``amplitude`` (default 10 deg) over the record (default 30 s).

    Slow enough (1/3 deg/s by default) that the car passes through near-steady
    states, so lateral acceleration against steer traces the handling curve up
    to the grip limit (0.79 g for the baseline, reached near 8 deg).
    """
    amplitude = _check_amplitude(10.0 * _DEG if amplitude is None else amplitude)
    seed = _check_seed(seed)
    duration = 30.0 if duration is None else duration
    n = _samples(duration, dt)
    t = dt * np.arange(n)
    return Manoeuvre("ramp", amplitude * t / t[-1], dt,
                     {"amplitude": amplitude, "duration": duration, "seed": seed})


_SCHEDULE_SPEED = 20.0  # [m/s] the speed at which a speed manoeuvre's steer amplitude holds


def _speed_scaled_steer(t: np.ndarray, speed: np.ndarray, amplitude: float, dt: float,
                        rng: np.random.Generator) -> np.ndarray:
    """Random steer (0-3 Hz, RMS ``amplitude`` at 20 m/s) scaled by ``(20 / V)^2``, faded in over 1 s.

    A car's lateral-acceleration gain grows about as V^2 (exactly so for a
    neutral car, ``V^2 / L``), so this scaling keeps the lateral acceleration
    of about the same size across the speed range: within the linear range at
    the top speed, still well above noise at the bottom.
    """
    noise = band_limited_noise(t.size, dt, 3.0, rng)
    return amplitude * (_SCHEDULE_SPEED / speed) ** 2 * _fade(t, 1.0) * noise


def speed_from_accelerations(t: np.ndarray, start_speed: float,
                              segments: list[tuple[float, float, float]], edge: float) -> np.ndarray:
    """Speed (N,) from ``start_speed`` under acceleration pulses ``(start s, length s, m/s^2)``.

    Each pulse rises and falls linearly over ``edge`` seconds (limited jerk), so
    the reference's rate, the speed hold's feed-forward, is continuous. The
    speed is the exact integral of the piecewise-linear acceleration.
    """
    def ramp_integral(x: np.ndarray) -> np.ndarray:  # integral of clip(x / edge, 0, 1) dx
        x = np.maximum(x, 0.0)
        return np.where(x < edge, x**2 / (2 * edge), x - edge / 2)

    speed = np.full(t.size, float(start_speed))
    for start, length, acceleration in segments:
        # a pulse = ramp up at start minus ramp up at start + length (each then held)
        speed += acceleration * (ramp_integral(t - start) - ramp_integral(t - start - length))
    return speed


def with_speed_profile(manoeuvre: Manoeuvre, speed: Any, *, name: str | None = None) -> Manoeuvre:
    """``manoeuvre`` with a reference speed profile (m/s, one value per sample, or a constant)."""
    profile = np.broadcast_to(np.asarray(speed, dtype=float), manoeuvre.steer.shape)
    return Manoeuvre(name or manoeuvre.name, manoeuvre.steer, manoeuvre.dt, dict(manoeuvre.meta), profile)


def speed_ramp(
    *, amplitude: float | None = None, duration: float | None = None, dt: float = DEFAULT_DT, seed: int = 0
) -> Manoeuvre:
    """Speed ramp from 10 to 35 m/s under random steer within the linear range.

    The reference holds 10 m/s for the first tenth of the record, rises at a
    constant rate (reached and left with a jerk-limited 2 s edge) to 35 m/s
    by nine tenths and holds it; default 60 s, so about 0.52 m/s^2. The steer
    is band-limited noise (0-3 Hz) of RMS ``amplitude`` (default 0.5 deg) at
    20 m/s, scaled by ``(20 / V)^2``: about 1 m/s^2 RMS lateral acceleration
    for the baseline saloon throughout, peaks within 0.4 g.
    """
    amplitude = _check_amplitude(0.5 * _DEG if amplitude is None else amplitude)
    seed = _check_seed(seed)
    duration = 60.0 if duration is None else duration
    n = _samples(duration, dt)
    t = dt * np.arange(n)
    low, high = 10.0, 35.0
    edge = min(2.0, 0.1 * duration)
    rise_start, rise_length = 0.1 * duration, 0.8 * duration - edge
    rate = (high - low) / rise_length  # the pulse's integral: rate * (rise_length) exactly
    speed = speed_from_accelerations(t, low, [(rise_start, rise_length, rate)], edge)
    rng = np.random.default_rng(seed)
    steer = _speed_scaled_steer(t, speed, amplitude, dt, rng)
    return Manoeuvre(
        "speed-ramp", steer, dt,
        {"amplitude": amplitude, "duration": duration, "seed": seed, "speed_range": [low, high],
         "acceleration": rate, "steer_band_hz": [0.0, 3.0], "steer_scaled_at_speed": _SCHEDULE_SPEED},
        speed,
    )


def speed_cycle(
    *, amplitude: float | None = None, duration: float | None = None, dt: float = DEFAULT_DT, seed: int = 0
) -> Manoeuvre:
    """Accelerate-brake cycle under random steer: 20 m/s, up to 30, braked to 12, back to 20.

    In fractions of the record (default 40 s): accelerate at 1.5 m/s^2 from
    0.1, brake at 3 m/s^2 (0.3 g, faster than coasting, so all four wheels
    brake) from 0.45, accelerate again at 1.5 m/s^2 from 0.75; each pulse's
    length is set so the speeds are reached exactly (6.7, 6 and 5.3 s), its
    edges jerk-limited over 0.5 s; a record shorter than about 36 s ends
    before the cycle does (the pulses then overlap, the speed stays within
    12-30 m/s). Steer as in :func:`speed_ramp`.
    """
    amplitude = _check_amplitude(0.5 * _DEG if amplitude is None else amplitude)
    seed = _check_seed(seed)
    duration = 40.0 if duration is None else duration
    n = _samples(duration, dt)
    t = dt * np.arange(n)
    edge = min(0.5, 0.02 * duration)
    changes = [(0.10, 30.0 - 20.0, 1.5), (0.45, 12.0 - 30.0, -3.0), (0.75, 20.0 - 12.0, 1.5)]
    # a pulse of level a and length T changes the speed by a T: T = change / a
    segments = [(fraction * duration, change / level, level) for fraction, change, level in changes]
    speed = speed_from_accelerations(t, 20.0, segments, edge)
    rng = np.random.default_rng(seed)
    steer = _speed_scaled_steer(t, speed, amplitude, dt, rng)
    return Manoeuvre(
        "speed-cycle", steer, dt,
        {"amplitude": amplitude, "duration": duration, "seed": seed, "speeds": [20.0, 30.0, 12.0, 20.0],
         "accelerations": [1.5, -3.0, 1.5], "steer_band_hz": [0.0, 3.0],
         "steer_scaled_at_speed": _SCHEDULE_SPEED},
        speed,
    )


# the names are listed once, in .choices, for the command line; each factory is the function of its name
MANOEUVRES: dict[str, Callable[..., Manoeuvre]] = {name: globals()[name.replace("-", "_")] for name in MANOEUVRE_NAMES}


def make_manoeuvre(name: str, **options: Any) -> Manoeuvre:
    """Make the manoeuvre called ``name``.

    Parameters
    ----------
    name : str
        A key of :data:`MANOEUVRES`: ``identification``, ``validation``, ``step``, ``sweep``,
        ``ramp``, ``speed-ramp`` or ``speed-cycle``.
    **options
        The manoeuvre's own keywords: amplitude (rad), duration (s), dt (s), seed, and its shape's.

    Returns
    -------
    Manoeuvre
        The steer series (and a speed profile for the speed manoeuvres).

    Examples
    --------
    >>> from vehid.vehicle import make_manoeuvre
    >>> step = make_manoeuvre("step", amplitude=0.01, duration=3.0)
    >>> step.n_samples, step.dt, float(step.steer[0]), float(step.steer[-1])
    (1501, 0.002, 0.0, 0.01)
    >>> step.meta["start"], step.meta["ramp_time"]
    (0.5, 0.1)
    """
    try:
        factory = MANOEUVRES[name]
    except KeyError:
        raise InputError(f"unknown manoeuvre {name!r}; choose from {', '.join(MANOEUVRES)}") from None
    return factory(**options)
