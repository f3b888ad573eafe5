"""Linearisation of the full-vehicle model at its trim: A, B, C, D and the modes.

Jacobians are exact (CasADi algorithmic differentiation of the same SX
expressions the simulator integrates). Each mode is an eigenvalue (a complex
pair counted once) with its undamped natural frequency, damping ratio, the
states that dominate it by participation factor, and a label.

Participation factors ``|w_ki v_ik|`` (left and right eigenvectors, ``W = V^-1``)
are independent of state units and scaling, so they name the states that take
part in a mode fairly (Perez-Arriaga, Verghese & Schweppe, IEEE Trans. PAS-101,
1982).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from vehid.identification.dataio.storage import register_codec

from .model import DEFAULT_SPEED, VehicleModel, build_vehicle_model, check_speed
from .parameters import VehicleParameters, named_vehicle

__all__ = ["VehicleMode", "Linearization", "linearize", "linearization_function", "MODE_GROUPS", "modes_of"]

# Which states make which kind of motion; a mode is labelled by the group with
# the largest share of its participation.
MODE_GROUPS = {
    "yaw-sideslip": ("v", "r"),
    "roll": ("phi", "p"),
    "pitch": ("theta", "q"),
    "heave": ("z", "w"),
    "wheel": ("omega_fl", "omega_fr", "omega_rl", "omega_rr",
              "kappa_fl", "kappa_fr", "kappa_rl", "kappa_rr"),
    "lateral-slip-lag": ("alpha_fl", "alpha_fr", "alpha_rl", "alpha_rr"),
    "speed": ("u", "speed_error_integral"),
    "heading": ("psi",),
}
_DOMINANT_SHARE = 0.1  # a state is listed as dominant above this share of a mode's participation


@dataclass(frozen=True)
class VehicleMode:
    """One mode of the linearised vehicle.

    Attributes
    ----------
    eigenvalue : complex
        Continuous-time eigenvalue (1/s); for a pair, the one with positive imaginary part.
    frequency_hz : float
        Undamped natural frequency ``|lambda| / (2 pi)`` (Hz).
    damping : float
        Damping ratio ``-Re(lambda) / |lambda|`` (1 for a stable real mode; NaN at lambda = 0).
    label : str
        Kind of motion: a key of :data:`MODE_GROUPS`.
    dominant_states : tuple of str
        States holding more than 10 % of the participation, largest first.
    """

    eigenvalue: complex
    frequency_hz: float
    damping: float
    label: str
    dominant_states: tuple[str, ...]

    @property
    def oscillatory(self) -> bool:
        """Whether the mode is a complex pair."""
        return abs(self.eigenvalue.imag) > 0

    def as_dict(self) -> dict:
        """Describe the mode for JSON (the ``modes`` entries of ``vehid linearize --json``).

        Returns
        -------
        dict
            Frequency, damping, label, eigenvalue and dominant states.
        """
        return {
            "frequency_hz": self.frequency_hz,
            "damping": self.damping,
            "label": self.label,
            "eigenvalue": self.eigenvalue,
            "dominant_states": list(self.dominant_states),
        }


@dataclass(frozen=True, eq=False)
class Linearization:
    """``dx/dt = A dx + B du``, ``dy = C dx + D du`` about the trim ``(x0, u0)`` at ``speed``.

    Attributes
    ----------
    A, B, C, D : ndarray
        Exact Jacobians, shapes (23, 23), (23, 1), (10, 23), (10, 1).
    x0 : ndarray, shape (23,)
        The trim states.
    u0 : ndarray, shape (1,)
        The trim steer (rad).
    speed : float
        Forward speed (m/s).
    state_names, input_names, output_names : tuple of str
        Names as in the model.
    modes : tuple of VehicleMode
        The modes, each labelled by its kind of motion, slowest first.
    vehicle : str
        The vehicle's name.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    x0: np.ndarray
    u0: np.ndarray
    speed: float
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    modes: tuple[VehicleMode, ...]
    vehicle: str

    def modes_labelled(self, label: str) -> tuple[VehicleMode, ...]:
        """Select the modes of one kind of motion.

        Parameters
        ----------
        label : str
            A key of :data:`MODE_GROUPS` (``"yaw-sideslip"``, ``"roll"``, ...).

        Returns
        -------
        tuple of VehicleMode
            The modes carrying ``label``, slowest first.
        """
        return tuple(mode for mode in self.modes if mode.label == label)


def modes_of(A: np.ndarray, state_names: tuple[str, ...]) -> tuple[VehicleMode, ...]:
    """Modes of a state matrix: eigenvalues, frequencies, damping, dominant states, labels; slowest first."""
    eigenvalues, right = np.linalg.eig(A)
    left = np.linalg.inv(right)
    participation = np.abs(left * right.T)  # participation[i, k] = |w_ik v_ki|
    groups = {name: [state_names.index(s) for s in states if s in state_names]
              for name, states in MODE_GROUPS.items()}
    modes = []
    for i, value in enumerate(eigenvalues):
        if value.imag < 0:
            continue  # the conjugate stands for the pair
        share = participation[i] / participation[i].sum()
        order = np.argsort(share)[::-1]
        dominant = tuple(state_names[k] for k in order if share[k] > _DOMINANT_SHARE)
        label = max(groups, key=lambda name: share[groups[name]].sum())
        magnitude = abs(value)
        damping = -value.real / magnitude if magnitude > 0 else math.nan
        eigenvalue = complex(value.real, value.imag if abs(value.imag) > 0 else 0.0)
        modes.append(VehicleMode(eigenvalue, magnitude / (2 * math.pi), float(damping), label, dominant))
    return tuple(sorted(modes, key=lambda mode: (mode.frequency_hz, mode.label)))


@functools.lru_cache(maxsize=16)
def linearization_function(model: VehicleModel) -> ca.Function:
    """``vehicle_linearization(x, u, p) -> (A, B, C, D)``: exact Jacobians, built once per model."""
    return ca.Function(
        "vehicle_linearization",
        [model.x, model.u, model.p],
        [ca.jacobian(model.xdot, model.x), ca.jacobian(model.xdot, model.u),
         ca.jacobian(model.y, model.x), ca.jacobian(model.y, model.u)],
        ["x", "u", "p"], ["A", "B", "C", "D"],
    )


def linearize(
    params: VehicleParameters | str = "baseline", *, speed: float = DEFAULT_SPEED, steer: float = 0.0
) -> Linearization:
    """Linearise the vehicle about its trim at ``speed`` (m/s) and constant ``steer`` (rad).

    Parameters
    ----------
    params : VehicleParameters or str, default "baseline"
        The vehicle, or a name or TOML/JSON file.
    speed : float, default DEFAULT_SPEED
        Forward speed (m/s), within the model's valid range.
    steer : float, default 0.0
        Constant road-wheel steer (rad) of the trim.

    Returns
    -------
    Linearization
        A, B, C, D (exact Jacobians), the trim and the modes.

    Examples
    --------
    The baseline's yaw-sideslip mode at 20 m/s, well damped as a near-neutral car's is:

    >>> from vehid.vehicle import linearize
    >>> linearization = linearize("baseline", speed=20.0)
    >>> linearization.A.shape, linearization.output_names[:2]
    ((23, 23), ('lateral_acceleration', 'yaw_rate'))
    >>> (mode,) = linearization.modes_labelled("yaw-sideslip")
    >>> round(float(mode.frequency_hz), 2), round(mode.damping, 2)
    (2.14, 0.98)
    """
    params = named_vehicle(params)
    speed = check_speed(speed, params)
    model = build_vehicle_model(params)
    x0 = model.trim(speed, steer)
    A, B, C, D = (np.asarray(m) for m in linearization_function(model)(x0, steer, speed))
    return Linearization(
        A=A, B=B, C=C, D=D, x0=x0, u0=np.array([float(steer)]), speed=speed,
        state_names=model.state_names, input_names=model.input_names, output_names=model.output_names,
        modes=modes_of(A, model.state_names), vehicle=params.name,
    )


#: The former name, kept so that code written against it keeps working; ``VehicleMode`` does not
#: collide with the identified models' :class:`vehid.identification.Mode`.
Mode = VehicleMode

register_codec(VehicleMode, "vehicle_mode", legacy_path="vehicle.linearize:Mode")
register_codec(Linearization, "vehicle_linearization", legacy_path="vehicle.linearize:Linearization")
