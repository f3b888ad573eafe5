"""A modal model's state over one sample, in CasADi SX: the discretisations its simulation and the filter share.

Two discretisations of ``xdot = A x + B u`` over a sample ``T``:

``euler``
    ``x + T (A x + B u0)``, the paper's; a filter on it converges to the Euler equivalent of the system.
``exact``
    ``x_next = e^{A T} x + T (phi1 - phi2)(A T) B u0 + T phi2(A T) B u1`` (first-order hold, the
    default; ``zoh`` holds the input), in closed form per modal block, by a Taylor series near ``z = 0``.
"""

from __future__ import annotations

from typing import Any

import casadi as ca

from ..choices import DISCRETIZATIONS
from ..errors import InputError
from .modal_structure import ModalStructure

__all__ = ["DISCRETIZATIONS", "check_discretization", "mode_transition", "modal_transition"]


_TAYLOR_RADIUS = 1e-3  # |z| below which phi1, phi2 use their series (error < |z|^4/120 ~ 1e-14)


def check_discretization(name: str) -> str:
    """Return ``name`` if it is a known discretisation, else raise InputError."""
    if name not in DISCRETIZATIONS:
        raise InputError(f"unknown discretization {name!r}; use one of {', '.join(DISCRETIZATIONS)}")
    return name


# Complex numbers as (re, im) pairs of SX scalars: the hold gains of a pair.
def _cmul(a: tuple, b: tuple) -> tuple:
    return (a[0] * b[0] - a[1] * b[1], a[0] * b[1] + a[1] * b[0])


def _phi_complex(zr: Any, zi: Any) -> tuple[tuple, tuple, tuple]:
    """``e^z``, ``phi1(z)``, ``phi2(z)`` for complex ``z = zr + j zi`` in SX, safe near zero."""
    modulus2 = zr * zr + zi * zi
    small = modulus2 < _TAYLOR_RADIUS**2
    # Evaluate the closed forms at a harmless point where the series is used,
    # so that neither branch ever divides by zero (if_else evaluates both).
    zr_safe = ca.if_else(small, 1.0, zr)
    zi_safe = ca.if_else(small, 0.0, zi)
    growth = ca.exp(zr_safe)
    er, ei = growth * ca.cos(zi_safe), growth * ca.sin(zi_safe)
    denominator = zr_safe * zr_safe + zi_safe * zi_safe
    inverse = (zr_safe / denominator, -zi_safe / denominator)
    phi1_closed = _cmul((er - 1.0, ei), inverse)
    phi2_closed = _cmul((phi1_closed[0] - 1.0, phi1_closed[1]), inverse)
    z = (zr, zi)
    z2 = _cmul(z, z)
    z3 = _cmul(z2, z)
    phi1_series = (
        1.0 + zr / 2 + z2[0] / 6 + z3[0] / 24,
        zi / 2 + z2[1] / 6 + z3[1] / 24,
    )
    phi2_series = (
        0.5 + zr / 6 + z2[0] / 24 + z3[0] / 120,
        zi / 6 + z2[1] / 24 + z3[1] / 120,
    )
    exact_growth = ca.exp(zr)
    e = (exact_growth * ca.cos(zi), exact_growth * ca.sin(zi))
    phi1 = (ca.if_else(small, phi1_series[0], phi1_closed[0]), ca.if_else(small, phi1_series[1], phi1_closed[1]))
    phi2 = (ca.if_else(small, phi2_series[0], phi2_closed[0]), ca.if_else(small, phi2_series[1], phi2_closed[1]))
    return e, phi1, phi2


def _phi_real(z: Any) -> tuple[Any, Any, Any]:
    """``e^z``, ``phi1(z)``, ``phi2(z)`` for real ``z`` in SX, safe near zero."""
    small = ca.fabs(z) < _TAYLOR_RADIUS
    z_safe = ca.if_else(small, 1.0, z)
    phi1_closed = (ca.exp(z_safe) - 1.0) / z_safe
    phi2_closed = (phi1_closed - 1.0) / z_safe
    phi1 = ca.if_else(small, 1.0 + z / 2 + z**2 / 6 + z**3 / 24, phi1_closed)
    phi2 = ca.if_else(small, 0.5 + z / 6 + z**2 / 24 + z**3 / 120, phi2_closed)
    return ca.exp(z), phi1, phi2


def mode_transition(
    sigma: Any,
    omega: Any | None,
    state: tuple[Any, ...],
    drive0: tuple[Any, ...],
    drive1: tuple[Any, ...],
    dt: float,
    discretization: str,
) -> tuple[Any, ...]:
    """One mode's state after a sample, in SX.

    Parameters
    ----------
    sigma, omega : SX
        The mode's real part and (for a pair) frequency; ``omega=None`` for a real pole.
    state : tuple of SX
        ``(x_a, x_b)`` for a pair, ``(x_a,)`` for a real pole.
    drive0, drive1 : tuple of SX
        The input terms ``B_row . u`` of each state at the start and end of the sample.
    dt : float
    discretization : {"euler", "exact", "exact-zoh"}

    Notes
    -----
    A pair's block ``[[sigma, omega], [-omega, sigma]]`` acts on
    ``x_a + j x_b`` as multiplication by ``sigma - j omega``.
    """
    if discretization == "euler":
        if omega is None:
            return (state[0] + dt * (sigma * state[0] + drive0[0]),)
        xa, xb = state
        return (
            xa + dt * (sigma * xa + omega * xb + drive0[0]),
            xb + dt * (-omega * xa + sigma * xb + drive0[1]),
        )
    if omega is None:
        e, phi1, phi2 = _phi_real(sigma * dt)
        if discretization == "exact-zoh":
            return (e * state[0] + dt * phi1 * drive0[0],)
        return (e * state[0] + dt * ((phi1 - phi2) * drive0[0] + phi2 * drive1[0]),)
    e, phi1, phi2 = _phi_complex(sigma * dt, -omega * dt)
    xi = _cmul(e, state)
    if discretization == "exact-zoh":
        forced = _cmul(phi1, drive0)
    else:
        gain0 = (phi1[0] - phi2[0], phi1[1] - phi2[1])
        forced0 = _cmul(gain0, drive0)
        forced1 = _cmul(phi2, drive1)
        forced = (forced0[0] + forced1[0], forced0[1] + forced1[1])
    return (xi[0] + dt * forced[0], xi[1] + dt * forced[1])


def modal_transition(
    structure: ModalStructure, modal: Any, x: Any, drive0: Any, drive1: Any, dt: float, discretization: str
) -> Any:
    """Every mode of a modal structure advanced over a sample (SX, n).

    ``modal`` holds each state's sigma/omega values in theta's modal order
    (pairs as sigma, omega; real poles as sigma), ``drive0``/``drive1`` the
    input terms of each state at the two ends of the sample.
    """
    rows: list[Any] = [None] * structure.n
    for states in structure.mode_states():
        a = states[0]
        if len(states) == 2:
            new = mode_transition(modal[a], modal[a + 1], (x[a], x[a + 1]), (drive0[a], drive0[a + 1]),
                                  (drive1[a], drive1[a + 1]), dt, discretization)
        else:
            new = mode_transition(modal[a], None, (x[a],), (drive0[a],), (drive1[a],), dt, discretization)
        for state, value in zip(states, new):
            rows[state] = value
    return ca.vertcat(*rows)
