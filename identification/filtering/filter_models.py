"""Symbolic models the Identifying EKF runs on: state transition and output in CasADi SX.

A filter model gives ``transition(x, theta, u0, u1, dt, discretization, constants) -> x_next`` and
``output(x, theta, u0, constants) -> y`` as SX expressions, so that the filter's Jacobians are exact
(Best & Bogdanski 2017, eq. 7-10); ``constants`` may change between passes without rebuilding the
compiled filter. The discretisations of a modal model's transition (``euler``, ``exact``, ``exact-zoh``)
are those of :mod:`vehid.identification.models.transition`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import casadi as ca

from ..models.modal_structure import ModalStructure
from ..models.transition import check_discretization, modal_transition

__all__ = ["FilterModel", "LinearModalFilterModel"]


class FilterModel(Protocol):
    """What the IEKF needs of a model (module docstring); ``n_constants`` is explicit, 0 where there are none."""

    @property
    def n_states(self) -> int: ...
    @property
    def n_theta(self) -> int: ...
    @property
    def n_u(self) -> int: ...
    @property
    def n_y(self) -> int: ...
    @property
    def n_constants(self) -> int: ...
    def transition(self, x: ca.SX, theta: ca.SX, u0: ca.SX, u1: ca.SX, dt: float, discretization: str,
                   constants: ca.SX) -> ca.SX: ...
    def output(self, x: ca.SX, theta: ca.SX, u: ca.SX, constants: ca.SX) -> ca.SX: ...
    def cache_key(self) -> str: ...


@dataclass(frozen=True)
class LinearModalFilterModel(FilterModel):
    """The linear modal model of :class:`ModalStructure` as a filter model."""

    structure: ModalStructure

    @property
    def n_states(self) -> int:
        return self.structure.n

    @property
    def n_theta(self) -> int:
        return self.structure.n_parameters

    @property
    def n_u(self) -> int:
        return self.structure.n_u

    @property
    def n_y(self) -> int:
        return self.structure.n_y

    n_constants = 0

    def transition(self, x: ca.SX, theta: ca.SX, u0: ca.SX, u1: ca.SX, dt: float, discretization: str,
                   constants: ca.SX | None = None) -> ca.SX:
        """``x_next`` (SX, n_states) under the given discretisation."""
        check_discretization(discretization)
        s = self.structure
        _, B, _, _ = s.matrices(theta, backend=ca.SX)
        drive0 = ca.mtimes(B, u0)
        drive1 = ca.mtimes(B, u1)
        return modal_transition(s, theta[: s.n_modal], x, drive0, drive1, dt, discretization)

    def output(self, x: ca.SX, theta: ca.SX, u: ca.SX, constants: ca.SX | None = None) -> ca.SX:
        """``y = C x + D u`` (SX, n_y)."""
        _, _, C, D = self.structure.matrices(theta, backend=ca.SX)
        return ca.mtimes(C, x) + ca.mtimes(D, u)

    def cache_key(self) -> str:
        """Text that identifies the symbolic model (for naming compiled code)."""
        return f"linear-modal:{self.structure.to_dict()}"
