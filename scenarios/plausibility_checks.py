"""Physical plausibility of the models the command line returns (:mod:`vehid.vehicle.plausibility`).

`vehid identify` and `vehid handling` check a model of a car after it is identified or read: its
handling metrics at each speed, its modes, and a single-track model's parameters and predicted sideslip.
Which output is which quantity is named as `vehid handling` names it: an output called ``yaw_rate``,
``lateral_acceleration`` or ``sideslip``, or ``quantities`` (``--quantities``: what each output
measures, in order, as for the single-track structure). :class:`CarChecks` is what
:func:`vehid.identification.identify` takes as its ``checks``. A model without a yaw-rate output is not
taken for a car and is not checked. Every failure joins the JSON list ``plausibility``
(``{quantity, value, range, speed, cause}``) and the warnings.

Speeds: a scheduled family's knots (the schedule taken as the speed in m/s) or the speeds asked;
a model of one speed at the speed its record states; a model of a drive over many speeds without
one is checked where speed does not matter (its transients and modes). A speed whose data are too few
(a knot marked extrapolated, a speed outside the log's range) is named as such
(:func:`extrapolated_speeds`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from vehid.identification.errors import WorkbenchError

__all__ = ["ROLES", "check_quantities", "CarChecks", "output_roles", "extrapolated_speeds", "model_findings", "record_findings",
           "handling_findings", "identify_findings", "single_track_findings", "single_track_sideslip"]

#: The quantities a car model's outputs are checked as.
ROLES = ("yaw_rate", "lateral_acceleration", "sideslip")


def check_quantities(quantities: Sequence[str], outputs: Sequence[str] = ()) -> tuple[str, ...]:
    """``quantities`` (what each output of a modal model measures, in order) checked before any work: each a
    quantity of the single-track model or ``other``, one per output where the outputs are named."""
    from vehid.identification.errors import OptionError
    from vehid.vehicle.single_track import QUANTITIES

    quantities = tuple(quantities)
    unknown = [q for q in quantities if q not in (*QUANTITIES, "other")]
    if unknown:
        raise OptionError(f"'quantities': unknown quantity {unknown[0]!r}; use {', '.join(QUANTITIES)} or other",
                          "quantities")
    if outputs and len(quantities) != len(outputs):
        raise OptionError(f"'quantities' names {len(quantities)} quantities for {len(outputs)} 'outputs' channels: "
                          "name what each output measures, in order (other for a channel of none)",
                          "quantities", "outputs")
    return quantities


def output_roles(output_names: Sequence[str], quantities: str | Sequence[str] | None = None) -> dict[str, int]:
    """Output index of each quantity of :data:`ROLES` the model has.

    ``quantities`` (``--quantities``: what each output measures, in order) names them where given and
    of the outputs' number; otherwise an output named as the quantity is taken (as `vehid handling` does).
    """
    if isinstance(quantities, str):
        quantities = [q.strip() for q in quantities.split(",") if q.strip()]
    names = list(quantities) if quantities and len(quantities) == len(output_names) else list(output_names)
    return {role: names.index(role) for role in ROLES if role in names}


def extrapolated_speeds(model: Any, speeds: Iterable[float]) -> tuple[float, ...]:
    """The speeds where the model rests on too few data: nearest a knot marked extrapolated
    (``meta["knot_coverage"]`` of a scheduled family), or outside the log's speed range (``speed_range``)."""
    speeds = [float(v) for v in speeds]
    coverage = (getattr(model, "meta", None) or {}).get("knot_coverage")
    sparse: list[float] = []
    if coverage:
        knots = np.array([float(knot["value"]) for knot in coverage])
        sparse = [v for v in speeds if coverage[int(np.argmin(np.abs(knots - v)))]["extrapolated"]]
    speed_range = getattr(model, "speed_range", None)
    if speed_range is not None:
        low, high = speed_range
        sparse += [v for v in speeds if not low <= v <= high and v not in sparse]
    return tuple(v for v in speeds if v in sparse)


def model_findings(model: Any, speeds: Sequence[float], *, roles: Mapping[str, int], steer: str | None = None,
                   wheelbase: float | None = None, scales: Mapping[str, float] | None = None,
                   band_hz: float | None = None, top_speed: float | None = None, speed_known: bool = True,
                   metrics: Sequence[Any] | None = None, lateral_feedthrough: bool = False) -> tuple[Any, ...]:
    """Findings on a model's handling metrics and modes at each speed (none where it has no yaw rate).

    ``metrics`` are the model's :func:`~vehid.vehicle.handling.handling_metrics` at ``speeds`` where
    already computed. A model the metrics cannot be computed for (an integrator, no steady state) is
    checked by its modes alone. ``lateral_feedthrough``: as :func:`vehid.vehicle.plausibility.handling_findings`.
    """
    from vehid.vehicle.handling import handling_metrics
    from vehid.vehicle.plausibility import EXTRAPOLATED_HINT, handling_findings, mode_findings, model_eigenvalues

    if "yaw_rate" not in roles:
        return ()
    scheduled = hasattr(model, "model_at")
    local = model.model_at(speeds[0]) if scheduled else model
    names = {role: tuple(local.output_names)[index] for role, index in roles.items()}
    sparse = extrapolated_speeds(model, speeds)
    findings: list[Any] = []
    if metrics is None:
        try:
            metrics = handling_metrics(model, speeds, steer=steer, wheelbase=wheelbase, scales=scales, **names)
        except (WorkbenchError, np.linalg.LinAlgError):
            metrics = ()
    findings += handling_findings(metrics, lateral_acceleration="lateral_acceleration" in roles, top_speed=top_speed,
                                  speed_known=speed_known, extrapolated=sparse, lateral_feedthrough=lateral_feedthrough)
    for speed in speeds if scheduled else speeds[:1]:
        at = model.model_at(speed) if scheduled else model
        hint = EXTRAPOLATED_HINT if speed in sparse else ""
        findings += mode_findings(model_eigenvalues(at), speed=speed if speed_known else None, band_hz=band_hz,
                                  hint=hint)
    return tuple(findings)


def record_findings(summary: dict[str, Any], warnings: list[str], findings: Iterable[Any]) -> None:
    """The findings as the summary's ``plausibility`` list and as warnings."""
    findings = list(findings)
    summary["plausibility"] = [finding.as_dict() for finding in findings]
    warnings.extend(finding.warning() for finding in findings)


def handling_findings(model: Any, speeds: Sequence[float], metrics: Sequence[Any], *, yaw_rate: str | None = None,
                      lateral_acceleration: str | None = None, sideslip: str | None = None
                      ) -> tuple[tuple[Any, ...], tuple[float, ...]]:
    """`vehid handling`'s checks: (findings, extrapolated speeds) of a model whose metrics are computed.

    The outputs are named as the metrics were (the options, else outputs called as the quantity); the
    fastest speed driven is the top of a single-track model's log or of a scheduled family's grid.
    """
    local = model.model_at(speeds[0]) if hasattr(model, "model_at") else model
    names = list(local.output_names)
    given = {"yaw_rate": yaw_rate, "lateral_acceleration": lateral_acceleration, "sideslip": sideslip}
    roles = {role: names.index(given[role] or role) for role in ROLES if (given[role] or role) in names}
    speed_range = getattr(model, "speed_range", None)
    top = float(speed_range[1]) if speed_range is not None else (
        float(model.grid[-1]) if hasattr(model, "grid") else max(speeds))
    return (model_findings(model, speeds, roles=roles, top_speed=top, metrics=metrics,
                           lateral_feedthrough=_single_track_without_lag(model)),
            extrapolated_speeds(model, speeds))


def _single_track_without_lag(model: Any) -> bool:
    """A single-track model without tyre lag: its lateral acceleration follows the steer at once by construction."""
    from vehid.vehicle.single_track import IdentifiedSingleTrack

    return isinstance(model, IdentifiedSingleTrack) and model.config.relaxation_length is None


@dataclass(frozen=True)
class CarChecks:
    """The checks of a car's physics on the model `vehid identify` returns (:func:`identify_findings`).

    :func:`vehid.identification.identify` takes them as its ``checks``.

    Attributes
    ----------
    quantities : tuple of str or None
        What each output measures, in order (:func:`check_quantities`); None: outputs named as the quantity.
    wheelbase : float or None
        The car's wheelbase (m), for the understeer gradient.
    """

    quantities: tuple[str, ...] | None = None
    wheelbase: float | None = None

    def __post_init__(self) -> None:
        if self.quantities is not None:
            object.__setattr__(self, "quantities", check_quantities(self.quantities))

    def __call__(self, model: Any, plan: Any) -> tuple[Any, ...] | None:
        return identify_findings(plan, model, quantities=self.quantities, wheelbase=self.wheelbase)


def identify_findings(plan: Any, model: Any, *, quantities: Sequence[str] | None = None,
                      wheelbase: float | None = None) -> tuple[Any, ...] | None:
    """Findings on the model `vehid identify` returns, or None where its outputs are not a car's.

    A scheduled family is checked at its knots, with the schedule's fastest value as the fastest speed
    driven; a model of one speed at its record's ``meta["speed"]``; otherwise where speed does not
    matter. The modes are weighed against the band the first input (the steer) excites. ``quantities``
    and ``wheelbase`` are :class:`CarChecks`'.
    """
    from vehid.vehicle.plausibility import steer_band_hz

    record = plan.records[0]
    roles = output_roles(record.output_names, quantities)
    if "yaw_rate" not in roles or not (hasattr(model, "model_at") or hasattr(model, "to_statespace")):
        return None
    schedule = getattr(plan, "schedule", None)
    top = float(max(np.max(s) for s in schedule.estimation)) if schedule is not None else None
    stated = record.meta.get("speed") if isinstance(record.meta, Mapping) else None
    if hasattr(model, "model_at"):
        speeds, known = [float(v) for v in model.grid], True
    elif isinstance(stated, (int, float)) and math.isfinite(stated) and stated > 0:
        speeds, known = [float(stated)], True
    else:
        speeds, known = [1.0], False  # the speed enters no check made without it
    band = steer_band_hz(record.u[:, 0], record.dt)
    return model_findings(model, speeds, roles=roles, wheelbase=wheelbase, band_hz=band, top_speed=top,
                          speed_known=known)


def single_track_findings(identified: Any, estimation: Sequence[Any],
                          sideslip: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[Any, ...]:
    """Findings on an identified single-track model: its parameters, its handling and modes at the log's
    speeds (its linearisation with yaw rate and lateral acceleration, whatever the log measured), and
    ``sideslip`` (measured, predicted) where the log has it. ``estimation`` holds the runs it was
    identified from; their steer sets the band the modes are weighed against."""
    import dataclasses

    from vehid.vehicle import plausibility
    from vehid.vehicle.single_track import IdentifiedSingleTrack

    config = identified.config
    findings = list(plausibility.single_track_findings(config, identified.parameters))
    # the car's own states, linearised where the slip angles are zero: the offsets do not move them
    car = IdentifiedSingleTrack(dataclasses.replace(config, quantities=("yaw_rate", "lateral_acceleration"),
                                                    offsets=False),
                                identified.parameters[:config.n_physical], None, identified.speed_range)
    longest = max(estimation, key=lambda run: run.n_samples)
    findings += model_findings(car, [float(v) for v in identified.grid], roles={"yaw_rate": 0, "lateral_acceleration": 1},
                               wheelbase=config.wheelbase,
                               band_hz=plausibility.steer_band_hz(longest.u[:, 0], longest.dt),
                               top_speed=identified.speed_range[1],
                               lateral_feedthrough=_single_track_without_lag(car))
    if sideslip is not None:
        findings += plausibility.sideslip_findings(*sideslip)
    return tuple(findings)


def single_track_sideslip(config: Any, parameters: np.ndarray, estimation: Sequence[Any],
                          measured: Sequence[np.ndarray] | None, substeps: int
                          ) -> tuple[np.ndarray, np.ndarray] | None:
    """(measured, predicted) sideslip over the estimation runs, joined, where the log measured it: an
    output of quantity ``sideslip``, or ``measured``, the ``--measured-sideslip`` channel on each run
    (read as the outputs are, times its ``--scale``, cleaned with them); None otherwise."""
    import dataclasses

    from vehid.identification.filtering.greybox_structure import simulate_greybox
    from vehid.vehicle.single_track import single_track_model

    if "sideslip" in config.quantities:
        measured = [run.y[:, config.quantities.index("sideslip")] for run in estimation]
    elif measured is None:
        return None
    theta = list(parameters[:config.n_physical]) + ([float(parameters[config.n_physical]), 0.0] if config.offsets else [])
    model = single_track_model(dataclasses.replace(config, quantities=("sideslip",)))
    predicted = []
    for run, values in zip(estimation, measured):
        record = run.replace(y=np.asarray(values, dtype=float)[:, None], output_names=("sideslip",),
                             output_units=("rad",))
        simulated, _ = simulate_greybox(model, theta, record, substeps=substeps)
        predicted.append(np.asarray(simulated, dtype=float)[:, 0])
    return np.concatenate([np.asarray(v, dtype=float) for v in measured]), np.concatenate(predicted)


