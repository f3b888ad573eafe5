"""A simulated drive from rest: what a logger records of the source model driven like a car on a track.

The twin of a measured drive (:mod:`vehid.vehicle.drive_calibration`): it starts and stops at rest,
accelerates to a top speed and brakes hard, corners at lateral accelerations up to near the grip
limit (braking into each corner, quasi-steady in its middle, accelerating out) and carries a small
random steer on its straights, so that a calibration meets what a real log holds, standstill included.

The source model is not valid below :data:`~vehid.vehicle.validity.MIN_SPEED`; there the drive runs
straight (no steer below :data:`STRAIGHT_BELOW`), where a car neither yaws nor accelerates sideways:
its yaw rate, lateral acceleration, roll and sideslip are exactly zero. Each stretch above that speed
is simulated from straight running at its first speed (:func:`~vehid.vehicle.calibration.simulated_log`:
a fine grid, inputs linear between samples), as the calibration drives it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from vehid.identification.errors import InputError

from .calibration import simulated_log
from .manoeuvres import speed_from_accelerations, band_limited_noise
from .model import OUTPUT_NAMES
from .parameters import VehicleParameters
from .validity import MIN_SPEED

__all__ = ["STRAIGHT_BELOW", "Drive", "drive_from_rest", "simulated_drive"]

#: Below this speed (m/s) the drive does not steer: the model's range starts at 3 m/s, and the
#: margin lets a stretch begin from straight running.
STRAIGHT_BELOW = 5.0

_EDGE = 0.5  # [s] jerk-limited edge of every acceleration pulse
_TRAIL = 2.0  # [m/s^2] braking into a corner's first part and accelerating out of its last
_STEER_RAMP = 1.5  # [s] a corner's steer rises and falls over this time
_UNDERSTEER_GUESS = 1.0 * math.pi / 180 / 9.81  # [rad per m/s^2] 1 deg/g: steer for a wanted lateral acceleration
_EXCITATION_DEG = 0.3  # RMS road-wheel steer (deg) at 20 m/s on the straights, 0-2 Hz, scaled by (20 / V)^2


@dataclass(frozen=True, eq=False)
class Drive:
    """A drive's inputs: time, road-wheel steer, speed and its rate (SI units, one row per sample)."""

    t: np.ndarray
    steer: np.ndarray
    speed: np.ndarray
    acceleration: np.ndarray
    meta: Mapping[str, Any] = field(default_factory=dict)

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])


def drive_from_rest(*, duration: float = 600.0, dt: float = 0.01, top_speed: float = 60.0,
                    lateral_acceleration: float = 8.0, braking: float = 8.0, wheelbase: float = 2.7,
                    seed: int = 0, stop_midway: bool = True) -> Drive:
    """A track-like drive from rest: straights, hard braking, corners, a stop midway, rest at the end.

    Parameters
    ----------
    duration : float
        Length (s); the drive ends braking to rest.
    dt : float
        Sample interval (s).
    top_speed : float
        The fastest straight's speed (m/s); the others draw theirs between 15 m/s and it.
    lateral_acceleration : float
        The hardest corner's lateral acceleration (m/s^2) aimed at; the corners draw theirs between
        30 % and 100 % of it. The steer is set for it by a linear single-track car of ``wheelbase``
        and 1 deg/g understeer, so the car reaches about that.
    braking : float
        Deceleration (m/s^2) of the braking from speed (the stops brake at 6 m/s^2 or less).
    seed : int
        Seed of the corners' order, directions and sizes and of the straights' random steer.
    stop_midway : bool
        Brake to rest halfway and stand for 3 s before driving on.

    Returns
    -------
    Drive
        ``acceleration`` is the speed's exact rate (the integral's integrand).
    """
    for name, value in (("duration", duration), ("dt", dt), ("top speed", top_speed),
                        ("lateral acceleration", lateral_acceleration), ("braking", braking), ("wheelbase", wheelbase)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise InputError(f"the drive's {name} must be a positive number; got {value!r}")
    if top_speed <= 20.0 or duration < 60.0:
        raise InputError("a drive from rest needs a top speed above 20 m/s and at least 60 s")
    rng = np.random.default_rng(seed)
    pulses: list[tuple[float, float, float]] = []  # (start, length, acceleration)
    corners: list[tuple[float, float, float]] = []  # (start, length, lateral acceleration)
    clock, speed = 3.0, 0.0  # 3 s at rest first
    fastest_done, stopped = False, not stop_midway
    end = duration - 12.0  # room to brake to rest from any speed at the end

    def change_speed(target: float, rate: float) -> None:
        nonlocal clock, speed
        length = abs(target - speed) / rate
        pulses.append((clock, length, math.copysign(rate, target - speed)))
        clock += length + _EDGE
        speed = target

    while clock < end:
        if not stopped and clock > duration / 2:
            change_speed(0.0, min(6.0, braking))
            clock += 3.0
            stopped = True
            continue
        if speed < STRAIGHT_BELOW:
            change_speed(15.0, 3.0)  # launch straight ahead
            continue
        target = top_speed if not fastest_done and clock > duration / 6 else float(rng.uniform(15.0, 0.85 * top_speed))
        fastest_done = fastest_done or target == top_speed
        straight = float(rng.uniform(2.0, 5.0))
        clock += straight  # a straight at the speed reached
        change_speed(target, 4.0 if target > speed else braking)
        # a corner at that speed: braked into, quasi-steady in its middle, driven out of, so that the load
        # moves between the axles as well as across them while the car corners
        length = float(rng.uniform(4.0, 9.0))
        size = float(rng.uniform(0.3, 1.0)) * lateral_acceleration * float(rng.choice([-1.0, 1.0]))
        corners.append((clock, length, size))
        pulses.append((clock + 0.15 * length, 0.25 * length, -_TRAIL))
        pulses.append((clock + 0.6 * length, 0.25 * length, _TRAIL))
        clock += length + _STEER_RAMP
        # brake to the next corner's speed when the car is fast
        if speed > 0.7 * top_speed:
            change_speed(float(rng.uniform(15.0, 0.5 * top_speed)), braking)
    change_speed(0.0, min(6.0, braking))
    n = int(round(max(duration, clock + 2.0) / dt)) + 1
    t = dt * np.arange(n)
    speed_profile = np.maximum(speed_from_accelerations(t, 0.0, pulses, _EDGE), 0.0)
    acceleration = np.gradient(speed_profile, dt)
    lateral = np.zeros(n)
    for start, length, size in corners:
        rise = np.clip((t - start) / _STEER_RAMP, 0.0, 1.0) - np.clip((t - start - length) / _STEER_RAMP, 0.0, 1.0)
        lateral += size * (0.5 - 0.5 * np.cos(np.pi * rise))
    moving = np.maximum(speed_profile, STRAIGHT_BELOW)
    steer = lateral * (wheelbase / moving**2 + _UNDERSTEER_GUESS)
    excitation = np.radians(_EXCITATION_DEG) * (20.0 / moving) ** 2 * band_limited_noise(n, dt, 2.0, rng)
    steer = steer + excitation
    # no steer at a crawl: a smooth fade from STRAIGHT_BELOW to twice it
    steer *= np.clip((speed_profile - STRAIGHT_BELOW) / STRAIGHT_BELOW, 0.0, 1.0)
    return Drive(t=t, steer=steer, speed=speed_profile, acceleration=acceleration,
                 meta={"duration": float(t[-1]), "top_speed": top_speed, "corners": len(corners),
                       "lateral_acceleration": lateral_acceleration, "seed": seed, "stop_midway": stop_midway})


def simulated_drive(params: VehicleParameters, drive: Drive, quantities: Sequence[str], *,
                    substeps: int = 10) -> np.ndarray:
    """The noise-free outputs (N, len(quantities)) of ``params`` driving ``drive`` (module notes).

    Below :data:`~vehid.vehicle.validity.MIN_SPEED` the car runs straight: every quantity of the
    lateral and roll motion is zero, the speed is the drive's; the tyre loads there are not offered.
    """
    unknown = [q for q in quantities if q not in OUTPUT_NAMES]
    if unknown:
        raise InputError(f"unknown quantity {unknown[0]!r}; the model offers {', '.join(OUTPUT_NAMES)}")
    if any(q.startswith("tyre_load") for q in quantities):
        raise InputError("a drive from rest records no tyre loads (the model does not hold at a standstill)")
    outputs = np.zeros((drive.t.size, len(quantities)))
    if "speed" in quantities:
        outputs[:, list(quantities).index("speed")] = drive.speed
    fast = drive.speed >= MIN_SPEED
    edges = np.flatnonzero(np.diff(np.concatenate([[0], fast.astype(np.int8), [0]])))
    for first, stop in zip(edges[::2], edges[1::2]):
        if np.any(np.abs(drive.steer[first:first + 1]) > 0):
            raise InputError("the drive steers where it enters the model's speed range: it must start straight")
        _, clean = simulated_log(params, drive.steer[first:stop], drive.speed[first:stop], drive.dt, quantities,
                                 substeps=substeps)
        outputs[first:stop] = clean
    return outputs
