"""Physical plausibility of an identified car model: what no car does, named with its likely cause.

A model can fit a log and still describe no car: steady gains that break the kinematics of a steady
turn, a yaw rate that answers the steer at once, an undamped mode in the band the steer excites, tyres
twenty times too soft. Each check here compares one quantity with a published range (:data:`RANGES`,
each range in this one place with its source) and returns a :class:`Finding` for every failure: the
quantity, its value, the range, the speed (m/s) where it fails, and the likely cause. The command
line gives them as the JSON list ``plausibility`` and as warnings.

The checks (axes, units and symbols of ``docs/conventions.md``; each bound in :data:`RANGES`):

* **steady turn** (:func:`handling_findings`): in a steady turn ``a_y = V r``, so a model with both
  outputs has a lateral-acceleration gain of ``V`` times its yaw-rate gain at every speed
  (``steady_turn_kinematic_ratio``, 1 within a tolerance);
* **steady-state handling**: an understeer gradient no car exceeds and, for an oversteering model, a
  critical speed above the fastest speed the car was driven at (else it would have spun);
* **step steer, ISO 7401**: yaw-rate and lateral-acceleration response times above zero (a response
  quicker than the tyres' own lag is a direct feed-through) and below what any car takes, the yaw
  rate's peak after its response time, its overshoot;
* **modes** (:func:`mode_findings`): every mode damped; the cause says whether the mode lies in the
  band the steer excites (:func:`steer_band_hz`) or above it (noise or vibration fitted);
* **single-track parameters** (:func:`single_track_findings`): each axle's normalised cornering
  stiffness ``C / F_z`` (``F_z`` its static load) and the dynamic index ``I_z / (m l_f l_r)``;
* **measured sideslip** (:func:`sideslip_findings`): the model's predicted sideslip correlates with the
  measured one.

Each range's bounds and why they are where they are: :data:`RANGES`. The causes are what the
workbench's own cases showed: a steering-wheel angle read as the road-wheel angle (``--scale`` of
the committed race-car log's steer by 15 gives a front ``C / F_z`` of 0.71 /rad, a dynamic index of
1.9 and an understeer gradient of 77 deg/g), units (deg/s, g), a knot with little data.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from .parameters import GRAVITY

__all__ = [
    "PlausibleRange",
    "RANGES",
    "EXTRAPOLATED_HINT",
    "Finding",
    "handling_findings",
    "mode_findings",
    "model_eigenvalues",
    "single_track_findings",
    "sideslip_findings",
    "steer_band_hz",
]


@dataclass(frozen=True)
class PlausibleRange:
    """Bounds within which a quantity of a car lies, its unit and where the bounds come from.

    ``low`` or ``high`` None: unbounded on that side (JSON null).
    """

    low: float | None
    high: float | None
    unit: str
    source: str

    def contains(self, value: float) -> bool:
        """Whether ``value`` lies within the bounds (a non-finite value does not)."""
        return math.isfinite(value) and (self.low is None or value >= self.low) and (
            self.high is None or value <= self.high)

    @property
    def bounds(self) -> tuple[float | None, float | None]:
        return self.low, self.high


_ISO_7401 = ("ISO 7401 step steer: yaw-rate response time of road cars 0.1-0.5 s (0.15-0.35 s for saloons at "
             "80-100 km/h), peak after it, overshoot usually below 50 %")
_RELAXATION = ("tyres lag the steer by their relaxation length over the speed, about 0.5 m: 10 ms at 50 m/s "
               "(Pacejka, Tire and Vehicle Dynamics, 2012, section 7.2); a quicker response is a direct feed-through")

#: Each checked quantity's range, unit and source. The bounds are those of the source where it gives
#: bounds of cars; where it gives a typical band, they are widened to what a single mistake (a steering
#: ratio left out, a unit, a knot with little data) leaves behind, as each source string says.
RANGES: Mapping[str, PlausibleRange] = MappingProxyType({
    "steady_turn_kinematic_ratio": PlausibleRange(
        0.85, 1.15, "-",
        "a steady turn has a_y = V r (ISO 8855 kinematics, beta constant): lateral-acceleration gain over V times "
        "the yaw-rate gain is 1. Tolerance 15 %: a body-fixed accelerometer also reads g sin(roll), up to 12 % at "
        "a saloon's 7 deg/g roll gradient (road cars 3-7 deg/g), plus a few per cent of sensor scale"),
    "understeer_gradient_deg_per_g": PlausibleRange(
        None, 6.0, "deg/g",
        "road cars about 0.5-5 deg/g, sports and race cars 0-2 (Gillespie, Fundamentals of Vehicle Dynamics, "
        "1992, ch. 6; ISO 4138); oversteer is checked by the critical speed"),
    "critical_speed_m_s": PlausibleRange(
        None, None, "m/s",
        "an oversteering car is unstable above its critical speed sqrt(-L/K) (Gillespie 1992, ch. 6): it must lie "
        "above the fastest speed the car was driven at without spinning"),
    "yaw_rate_response_time_s": PlausibleRange(0.01, 1.0, "s", f"{_ISO_7401}; at most twice the slowest; {_RELAXATION}"),
    "yaw_rate_peak_response_time_s": PlausibleRange(
        0.01, 1.5, "s", f"{_ISO_7401}; the peak follows the response time, within three times the slowest response"),
    "yaw_rate_overshoot": PlausibleRange(0.0, 0.5, "-", _ISO_7401),
    "lateral_acceleration_response_time_s": PlausibleRange(
        0.01, 1.5, "s", f"ISO 7401: the lateral acceleration follows the yaw rate; {_RELAXATION}"),
    "mode_damping": PlausibleRange(
        0.1, None, "-",
        "a car's yaw and sideslip mode is well damped (the single-track model's closed form gives 0.40 at 60 m/s "
        "for the committed race-car log's car, falling as 1/V: below 0.1 only beyond 200 m/s); an undamped mode "
        "in the steer's band is not a car's, one above it is noise or vibration fitted by the model"),
    "normalised_cornering_stiffness_per_rad": PlausibleRange(
        2.0, 40.0, "/rad",
        "axle cornering stiffness over its static load: tyres' cornering coefficient 0.08-0.19 per degree "
        "(4.6-10.9 /rad), low-profile tyres up to 0.3 per degree (17 /rad) (Gillespie 1992, ch. 10); bounds "
        "below half the lowest and above twice the highest: a steering-wheel angle (ratio 12-20) makes "
        "5-20 /rad 0.25-1.7"),
    "dynamic_index": PlausibleRange(
        0.5, 1.5, "-",
        "I_z / (m l_f l_r) is about 0.8-1.2 for most cars (Milliken and Milliken, Race Car Vehicle Dynamics, "
        "1995); below 0.5 most of the mass would sit within a few tenths of a metre of "
        "the CG, above 1.5 beyond the axles"),
    "sideslip_correlation": PlausibleRange(
        0.5, 1.0, "-",
        "the predicted sideslip follows the measured one (the committed race-car log's linear single-track: "
        "0.97); below 0.5 it explains less than a quarter of the measured sideslip's variance"),
})


def _number(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


@dataclass(frozen=True)
class Finding:
    """One failed plausibility check: a frozen value.

    Attributes
    ----------
    quantity : str
        What was checked (a key of :data:`RANGES`, the axle added to a cornering stiffness).
    value : float
        Its value, in the range's unit.
    range : (float or None, float or None)
        The bounds it fails (None: unbounded).
    speed : float or None
        The speed (m/s) where it fails; None where the quantity does not depend on speed.
    cause : str
        The likely cause, in words.
    unit : str
        The unit of value and range.
    """

    quantity: str
    value: float
    range: tuple[float | None, float | None]
    speed: float | None
    cause: str
    unit: str = "-"

    def as_dict(self) -> dict[str, Any]:
        """The JSON entry: ``quantity``, ``value``, ``range`` ([low, high], null unbounded), ``speed``, ``cause``."""
        return {"quantity": self.quantity, "value": _number(self.value),
                "range": [_number(self.range[0]), _number(self.range[1])], "speed": _number(self.speed),
                "cause": self.cause}

    def warning(self) -> str:
        """The warning naming the quantity, speed, value, range and cause."""
        low, high = self.range
        unit = "" if self.unit == "-" else f" {self.unit}"
        bounds = (f"{low:.3g}-{high:.3g}" if low is not None and high is not None
                  else f">= {low:.3g}" if low is not None else f"<= {high:.3g}")
        where = "" if self.speed is None else f" at {self.speed:.4g} m/s"
        return (f"implausible {self.quantity}{where}: {self.value:.3g}{unit}, outside "
                f"{bounds}{unit}: {self.cause}")


def _check(quantity: str, value: float, speed: float | None, cause: str, *, name: str | None = None,
           bounds: tuple[float | None, float | None] | None = None) -> list[Finding]:
    """[Finding] where ``value`` lies outside the range of ``quantity`` (or ``bounds``), else []."""
    reference = RANGES[quantity]
    if bounds is not None:
        reference = PlausibleRange(*bounds, reference.unit, reference.source)
    if not math.isfinite(value) or reference.contains(value):
        return []
    return [Finding(name or quantity, float(value), reference.bounds, speed, cause, reference.unit)]


#: factors a ratio of two gains takes when one output is in another unit: (factor, what it means)
_UNIT_FACTORS = ((180.0 / math.pi, "the yaw rate in rad/s where deg/s was meant, or the lateral acceleration in "
                                   "deg-based units"),
                 (math.pi / 180.0, "the yaw rate in deg/s (convert with --scale CHANNEL=0.0174533)"),
                 (GRAVITY, "the lateral acceleration in m/s^2 where g was meant"),
                 (1.0 / GRAVITY, "the lateral acceleration in g (convert with --scale CHANNEL=9.81)"),
                 (-1.0, "one output of opposite sign (ISO 8855: a left turn has yaw rate and lateral acceleration "
                        "positive; flip it with --scale CHANNEL=-1)"))


#: Added to a finding's cause at a speed where the model rests on too few samples.
EXTRAPOLATED_HINT = " (too few samples at this speed: the model is extrapolated here)"


def _kinematic_cause(ratio: float, extrapolated: bool) -> str:
    for factor, meaning in _UNIT_FACTORS:
        if abs(ratio / factor - 1.0) < 0.15:
            return f"a ratio near {factor:.3g}: {meaning}"
    if extrapolated:
        return "the model's steady gains are not a car's here: too few samples at this speed (marked extrapolated)"
    return ("the model's steady gains are not a car's here: the log holds too little steady cornering at this "
            "speed to fix them (a scheduled model's knot where the car seldom holds a turn), outputs that are not "
            "the yaw rate and lateral acceleration at the CG, or a schedule that is not the speed in m/s")


def handling_findings(metrics: Iterable[Any], *, lateral_acceleration: bool, top_speed: float | None = None,
                      speed_known: bool = True, extrapolated: Iterable[float] = (),
                      lateral_feedthrough: bool = False) -> tuple[Finding, ...]:
    """Findings on the handling metrics of a model (:class:`~vehid.vehicle.handling.HandlingMetrics`).

    Parameters
    ----------
    metrics : iterable of HandlingMetrics
        One per speed.
    lateral_acceleration : bool
        Whether the model has a lateral-acceleration output: the steady-turn kinematics and the
        lateral acceleration's response time are checked only then.
    top_speed : float, optional
        The fastest speed (m/s) the car was driven at; default the fastest of ``metrics``.
    speed_known : bool
        False for a model whose speed is not known (an unscheduled model of a drive over many
        speeds): only the checks that do not depend on speed (the transients) are made, without a speed.
    extrapolated : iterable of float
        Speeds whose data are marked too few: named in the causes.
    lateral_feedthrough : bool
        The model has a direct feed-through from steer to lateral acceleration by construction (the
        linear single-track model without tyre lag: its front axle's force follows the steer at once),
        so a lateral-acceleration response time of 0 is its structure, not a fault of the fit: only
        its upper bound is checked.

    Returns
    -------
    tuple of Finding
    """
    metrics = list(metrics)
    sparse = {float(v) for v in extrapolated}
    top = top_speed if top_speed is not None else max((m.speed for m in metrics), default=None)
    findings: list[Finding] = []
    for m in metrics:
        speed = m.speed if speed_known else None
        thin = m.speed in sparse
        hint = EXTRAPOLATED_HINT if thin else ""
        if speed_known and lateral_acceleration and m.yaw_rate_gain != 0:
            ratio = m.lateral_acceleration_gain / (m.speed * m.yaw_rate_gain)
            findings += _check("steady_turn_kinematic_ratio", ratio, speed, _kinematic_cause(ratio, thin))
        if speed_known:
            gradient = m.understeer_gradient_deg_per_g
            findings += _check("understeer_gradient_deg_per_g", gradient, speed,
                               "far more understeer than any car's: a steer channel that is the steering-wheel angle "
                               "(give --steering-ratio, typically 12-20) or in degrees, or steady gains resting on "
                               "too little data at this speed" + hint)
            if top is not None and math.isfinite(m.critical_speed_m_s):
                findings += _check("critical_speed_m_s", m.critical_speed_m_s, speed,
                                   f"the model oversteers and would spin above {m.critical_speed_m_s:.3g} m/s, yet the "
                                   f"car was driven at {top:.3g} m/s: the balance between its axles is wrong (axle "
                                   "distances, a steer channel of the wrong scale) or it extrapolates" + hint,
                                   bounds=(float(top), None))
        findings += _check("yaw_rate_response_time_s", m.yaw_rate_response_time_s, speed,
                           "the yaw rate answers the steer at once: a direct feed-through from steer to yaw rate (the "
                           "model's D), which a car does not have (its tyres must first build a yaw moment)"
                           if m.yaw_rate_response_time_s < RANGES["yaw_rate_response_time_s"].low else
                           "slower than any car's yaw response: a slow mode fitted to drift or to the change of "
                           "speed" + hint)
        peak, response = m.yaw_rate_peak_response_time_s, m.yaw_rate_response_time_s
        if math.isfinite(peak):
            low = max(RANGES["yaw_rate_peak_response_time_s"].low, response if math.isfinite(response) else 0.0)
            findings += _check("yaw_rate_peak_response_time_s", peak, speed,
                               "the yaw rate peaks before it reaches 90 % of its steady value: not a car's step "
                               "response (a direct feed-through)" if peak <= low else
                               "the yaw rate peaks later than any car's: a slow, lightly damped mode" + hint,
                               bounds=(low, RANGES["yaw_rate_peak_response_time_s"].high))
        above = speed_known and math.isfinite(m.characteristic_speed_m_s) and m.speed > m.characteristic_speed_m_s
        findings += _check("yaw_rate_overshoot", m.yaw_rate_overshoot, speed,
                           (f"above its characteristic speed ({m.characteristic_speed_m_s:.3g} m/s) the linear model's "
                            "steady yaw gain falls while its first response does not: a transient beyond the ISO 7401 "
                            "speeds, resting on axle stiffnesses averaged over the whole log" if above else
                            "a lightly damped yaw mode, which a car's tyres and yaw inertia do not give") + hint)
        if lateral_acceleration:
            bounds = (None, RANGES["lateral_acceleration_response_time_s"].high) if lateral_feedthrough else None
            findings += _check("lateral_acceleration_response_time_s", m.lateral_acceleration_response_time_s, speed,
                               "the lateral acceleration answers the steer at once: a direct feed-through (the model's "
                               "D), where a car's tyres build their force over their relaxation length"
                               if m.lateral_acceleration_response_time_s
                               < RANGES["lateral_acceleration_response_time_s"].low else
                               "slower than any car's lateral response: a slow mode fitted to drift" + hint,
                               bounds=bounds)
    return _speed_free(findings, len(metrics))


def _speed_free(findings: list[Finding], speeds: int) -> tuple[Finding, ...]:
    """The findings, with a quantity that fails alike at every one of the ``speeds`` given once, without a
    speed: a single-track model's understeer gradient does not depend on speed (its linearisation's speed
    floor moves it by 4e-4 at 10 m/s, so alike is within 0.1 %)."""
    merged: list[Finding] = []
    for finding in findings:
        group = [other for other in findings if other.quantity == finding.quantity]
        alike = speeds > 1 and len(group) == speeds and all(
            math.isclose(other.value, group[0].value, rel_tol=1e-3) for other in group)
        if not alike:
            merged.append(finding)
        elif finding is group[0]:
            merged.append(dataclasses.replace(finding, speed=None))
    return tuple(merged)


def model_eigenvalues(model: Any) -> np.ndarray:
    """The continuous-time eigenvalues (1/s) of a linear model (``to_statespace``; ``log(z) / dt`` if discrete)."""
    A, _, _, _, dt = model.to_statespace()
    eigenvalues = np.linalg.eigvals(np.asarray(A, dtype=float))
    if dt is None:
        return eigenvalues
    with np.errstate(divide="ignore"):
        return np.log(eigenvalues.astype(complex)) / float(dt)


def mode_findings(eigenvalues: Any, *, speed: float | None = None, band_hz: float | None = None,
                  hint: str = "") -> tuple[Finding, ...]:
    """A finding per mode damped less than :data:`RANGES` ``mode_damping`` allows (unstable ones included).

    Parameters
    ----------
    eigenvalues : array_like
        Continuous-time eigenvalues (1/s) of the model at one speed (:func:`model_eigenvalues`).
    speed : float, optional
        The speed (m/s) they hold at.
    band_hz : float, optional
        Upper edge of the band the steer excites (:func:`steer_band_hz`); names whether a mode lies in it.
    hint : str
        Added to each cause (what else is known of this speed).
    """
    eigenvalues = np.asarray(eigenvalues, dtype=complex).ravel()
    findings: list[Finding] = []
    seen: set[tuple[float, float]] = set()
    for value in eigenvalues:
        if value.imag < 0:  # one of each pair
            continue
        size = abs(value)
        if size == 0:
            continue
        frequency, damping = size / (2 * math.pi), -value.real / size
        key = (round(frequency, 9), round(damping, 9))
        if key in seen:
            continue
        seen.add(key)
        if damping < 0:
            cause = f"an unstable mode at {frequency:.3g} Hz: no car is unstable in its linear range below its critical speed"
        elif band_hz is None:
            cause = (f"a lightly damped mode at {frequency:.3g} Hz: a car's handling mode is well damped; noise or "
                     "vibration fitted by the model, or a mode at a knot with little data")
        elif frequency <= band_hz:
            cause = (f"a lightly damped mode at {frequency:.3g} Hz, inside the {band_hz:.2g} Hz the steer excites: not a "
                     "car's handling mode; too little data at this speed, or a model order beyond what the log holds")
        else:
            cause = (f"a lightly damped mode at {frequency:.3g} Hz, above the {band_hz:.2g} Hz the steer excites: noise "
                     "or vibration (chassis, sensor mount) fitted by the model; try a lower --order")
        findings += _check("mode_damping", damping, speed, cause + hint)
    return tuple(findings)


#: the steer's band ends where its power spectral density falls this far below its peak (-40 dB: 1 % in
#: amplitude): on the committed race-car log and its 550 s drive at 2.9 and 3.0 Hz, unmoved by the
#: drive's one-sample 0.48 rad spike (a 99.9 % share of the variance would put it at 44 Hz there)
STEER_BAND_LEVEL = 1e-4
_WELCH_SECONDS = 10.24  # Welch segments: a tenth of a hertz apart, several per minute of log


def steer_band_hz(steer: Any, dt: float) -> float | None:
    """Upper edge (Hz) of the band the steer excites: the highest frequency where its power spectral
    density (Welch) is within :data:`STEER_BAND_LEVEL` of its peak; None for a record too short or flat."""
    from scipy.signal import welch

    steer = np.asarray(steer, dtype=float).ravel()
    segment = min(steer.size, int(round(_WELCH_SECONDS / dt)))
    if segment < 16 or not np.all(np.isfinite(steer)):
        return None
    frequencies, power = welch(steer - steer.mean(), fs=1.0 / dt, nperseg=segment)
    if not power.max() > 0:
        return None
    return float(frequencies[np.flatnonzero(power >= STEER_BAND_LEVEL * power.max())[-1]])


def _stiffness_cause(axle: str, low: bool, other_fails: bool) -> str:
    if axle == "front" and low and not other_fails:
        return ("only the front axle is soft: the steer channel is probably not the road-wheel angle (a "
                "steering-wheel angle needs --steering-ratio, typically 12-20; a steer in degrees a --scale of "
                "0.0174533)")
    if low:
        return ("both axles soft: the lateral acceleration or yaw rate in other units (g, deg/s: convert with "
                "--scale), or a steer channel that is not the road-wheel angle")
    if axle == "front" and not other_fails:
        return ("only the front axle is stiff: a steer channel already at the road wheel divided by a steering ratio "
                "(--steering-ratio), or a steer scale too small")
    return (f"the {axle} axle's stiffness is not determined by the log: the balance between axles is wrong (check "
            "--mass, --lf, --lr), or a saturating axle whose slope the log does not reach")


def single_track_findings(config: Any, parameters: Sequence[float]) -> tuple[Finding, ...]:
    """Findings on a single-track model's cornering stiffnesses and yaw inertia against published ranges.

    Parameters
    ----------
    config : SingleTrackConfig
        Mass and axle distances (:mod:`vehid.vehicle.single_track`).
    parameters : sequence of float
        ``C_f``, ``C_r`` (N/rad), ``I_z`` (kg m^2), as :func:`~vehid.vehicle.single_track.single_track_model` orders them.
    """
    c_front, c_rear, inertia = (float(p) for p in parameters[:3])
    load_front, load_rear = config.axle_loads
    normalised = {"front": c_front / load_front, "rear": c_rear / load_rear}
    reference = RANGES["normalised_cornering_stiffness_per_rad"]
    fails = {axle: not reference.contains(value) for axle, value in normalised.items()}
    findings: list[Finding] = []
    for axle, value in normalised.items():
        other = fails["rear" if axle == "front" else "front"]
        findings += _check("normalised_cornering_stiffness_per_rad", value, None,
                           _stiffness_cause(axle, value < reference.low, other),
                           name=f"normalised_cornering_stiffness_{axle}_per_rad")
    index = inertia / (config.mass * config.cg_to_front_axle * config.cg_to_rear_axle)
    findings += _check("dynamic_index", index, None,
                       "the yaw inertia has absorbed something else: " + (
                           "it follows the front axle's stiffness (the steer channel's scale)" if fails["front"] else
                           "mass or axle distances that are not the car's (--mass, --lf, --lr), or a lag the model "
                           "lacks (--relaxation-length)"))
    return tuple(findings)


#: a correlation below this is a reversed sign more likely than a model's wrong balance: the committed
#: race-car log's linear single-track predicts its sideslip with 0.97, a balance gone wrong (its 550 s
#: drive with --saturation) gave -0.52
_REVERSED_SIDESLIP = -0.8


def sideslip_findings(measured: Any, predicted: Any) -> tuple[Finding, ...]:
    """A finding where the model's predicted sideslip does not follow the measured one (sign and correlation).

    Parameters
    ----------
    measured, predicted : array_like (N,)
        Sideslip (rad, ISO 8855: positive when the CG moves to the left of the heading), sample for sample.
    """
    measured, predicted = (np.asarray(a, dtype=float).ravel() for a in (measured, predicted))
    keep = np.isfinite(measured) & np.isfinite(predicted)
    if keep.sum() < 3 or np.std(measured[keep]) == 0 or np.std(predicted[keep]) == 0:
        return ()
    correlation = float(np.corrcoef(measured[keep], predicted[keep])[0, 1])
    if correlation < _REVERSED_SIDESLIP:
        cause = ("the predicted sideslip runs opposite to the measured one: a sensor of the other sign convention "
                 "(flip it with --scale CHANNEL=-1), or a model whose balance between front and rear axle is "
                 "reversed, even where yaw rate and lateral acceleration fit")
    else:
        cause = ("the model gets the balance between front and rear axle wrong, even where yaw rate and lateral "
                 "acceleration fit: its axle stiffnesses are not the car's (a saturating axle the log does not "
                 "determine, axle distances)")
    return tuple(_check("sideslip_correlation", correlation, None, cause))
