"""Combined-slip, load-dependent Magic Formula tyre (MF 6.2 at zero camber), smooth and branch-free.

Equations from Pacejka, Tire and Vehicle Dynamics, 3rd ed. (2012), section
4.3.2: pure longitudinal slip (eq. 4.E9-4.E18), pure lateral slip
(eq. 4.E19-4.E30) and combined slip with cosine weighting functions
(eq. 4.E50-4.E67), with camber gamma = 0, pressure change dpi = 0, no turn
slip, all scaling factors 1 and every shift term zero (so that the combined
weights are normalised by 1). Signs follow ISO-W (TYDEX): positive slip ratio
kappa drives, positive slip angle alpha (wheel moving to its left) gives a
negative lateral force.

Sign functions (``sgn`` in eq. 4.E14 and 4.E24) are replaced by the
algebraic ``x / sqrt(x^2 + eps^2)`` (cheaper than ``tanh``) so that the
code stays differentiable; the curvature factors
of this tyre never exceed 1 over the loads of interest, so the ``E <= 1``
clip of the book is not needed and is left out (it would add a kink).

The curvature asymmetry term PEY3 makes a tyre's lateral characteristic
slightly different for positive and negative slip. The right-hand tyres are
mounted mirrored (their characteristic is the left tyre's reflected,
``F_y,R(alpha) = -F_y,L(-alpha)``), which keeps the car exactly left/right
symmetric.

The aligning moment (:func:`aligning_moment`) is the pneumatic trail times
the lateral force, ``M_z = -t F_y`` (eq. 4.E31-4.E44 at pure slip, 4.E71-4.E78
in combined slip, where the trail falls with the equivalent slip
``sqrt(alpha^2 + (K_xk / K_ya)^2 kappa^2)``). At zero camber the residual
moment ``M_zr`` is a constant offset of about 2 N m (QDZ6) and the ``s F_x``
term a left/right asymmetry; both are shift-like and, like the shift terms,
left out.

``friction_scale`` (LMUX = LMUY) multiplies both peak forces; the slip
stiffnesses stay (eq. 4.E13, 4.E25), so a sticky tyre grips more without
cornering harder at small slip.

The functions take CasADi SX (or plain floats) and return the same kind.
"""

from __future__ import annotations

import casadi as ca

from .parameters import TyreParameters, lateral_curvature, longitudinal_curvature

__all__ = [
    "SIGN_SMOOTHING_SLIP",
    "load_increment",
    "cornering_stiffness",
    "longitudinal_slip_stiffness",
    "lateral_force_pure",
    "longitudinal_force_pure",
    "combined_forces",
    "pneumatic_trail",
    "aligning_moment",
]

SIGN_SMOOTHING_SLIP = 1e-3  # width of the smooth sgn(x) on slip (-, rad)
_EPS_FORCE = 0.1  # epsilon_x, epsilon_y of eq. 4.E18/4.E26 (N): avoids 0/0 at zero load


def _smooth_sign(x):
    return x / ca.sqrt(x * x + SIGN_SMOOTHING_SLIP**2)


def load_increment(fz, tyre: TyreParameters):
    """Normalised load change ``dfz = (F_z - F_z0) / F_z0`` (eq. 4.E2a)."""
    return (fz - tyre.nominal_load) / tyre.nominal_load


def cornering_stiffness(fz, tyre: TyreParameters, scale: float = 1.0):
    """Cornering stiffness ``K_ya`` (N/rad, negative in ISO signs), eq. 4.E25 at gamma = 0.

    ``scale`` multiplies the result (the LKY scaling factor).
    """
    fz0 = tyre.nominal_load
    return scale * tyre.PKY1 * fz0 * ca.sin(tyre.PKY4 * ca.atan(fz / (tyre.PKY2 * fz0)))


def longitudinal_slip_stiffness(fz, tyre: TyreParameters):
    """Longitudinal slip stiffness ``K_xk`` (N per unit slip), eq. 4.E15."""
    dfz = load_increment(fz, tyre)
    return fz * (tyre.PKX1 + tyre.PKX2 * dfz) * ca.exp(tyre.PKX3 * dfz)


def _magic(b, c, d, e, x):
    bx = b * x
    return d * ca.sin(c * ca.atan(bx - e * (bx - ca.atan(bx))))


def longitudinal_force_pure(kappa, fz, tyre: TyreParameters):
    """``F_x0`` (N) under pure longitudinal slip, eq. 4.E9-4.E18."""
    dfz = load_increment(fz, tyre)
    c = tyre.PCX1
    d = (tyre.PDX1 + tyre.PDX2 * dfz) * tyre.friction_scale * fz
    e = longitudinal_curvature(dfz, _smooth_sign(kappa), tyre)
    b = longitudinal_slip_stiffness(fz, tyre) / (c * d + _EPS_FORCE)
    return _magic(b, c, d, e, kappa)


def lateral_force_pure(alpha, fz, tyre: TyreParameters, *, scale: float = 1.0, mirrored: bool = False):
    """``F_y0`` (N) under pure lateral slip, eq. 4.E19-4.E30.

    ``alpha`` is the slip ``tan(alpha)`` (rad); ``mirrored`` reflects the
    curvature asymmetry for a tyre on the right-hand side.
    """
    dfz = load_increment(fz, tyre)
    c = tyre.PCY1
    d = (tyre.PDY1 + tyre.PDY2 * dfz) * tyre.friction_scale * fz
    side = -1.0 if mirrored else 1.0
    e = lateral_curvature(dfz, _smooth_sign(side * alpha), tyre)
    b = cornering_stiffness(fz, tyre, scale) / (c * d + _EPS_FORCE)
    return _magic(b, c, d, e, alpha)


def _weight(b, c, e, x):
    bx = b * x
    return ca.cos(c * ca.atan(bx - e * (bx - ca.atan(bx))))


def combined_forces(kappa, alpha, fz, tyre: TyreParameters, *, scale: float = 1.0, mirrored: bool = False):
    """Longitudinal and lateral force (N) under combined slip, eq. 4.E50-4.E67.

    Parameters
    ----------
    kappa : SX or float
        Longitudinal slip ratio (-), positive when driving.
    alpha : SX or float
        Lateral slip ``tan(alpha)`` (-), positive when the contact point moves to the wheel's left.
    fz : SX or float
        Vertical load (N), non-negative.
    tyre : TyreParameters
        Coefficients.
    scale : float
        Cornering-stiffness scaling (LKY).
    mirrored : bool
        True for a right-hand tyre (see the module notes).

    Returns
    -------
    (F_x, F_y) : tuple
        Forces in the wheel's ISO axes (N).
    """
    dfz = load_increment(fz, tyre)
    fx0 = longitudinal_force_pure(kappa, fz, tyre)
    fy0 = lateral_force_pure(alpha, fz, tyre, scale=scale, mirrored=mirrored)
    # cos(atan(B2 x)) written as 1/sqrt(1 + (B2 x)^2): same value, no trigonometry.
    b_xa = tyre.RBX1 / ca.sqrt(1 + (tyre.RBX2 * kappa) ** 2)
    g_xa = _weight(b_xa, tyre.RCX1, tyre.REX1 + tyre.REX2 * dfz, alpha)
    b_yk = tyre.RBY1 / ca.sqrt(1 + (tyre.RBY2 * (alpha - tyre.RBY3)) ** 2)
    g_yk = _weight(b_yk, tyre.RCY1, tyre.REY1 + tyre.REY2 * dfz, kappa)
    return g_xa * fx0, g_yk * fy0


def pneumatic_trail(kappa, alpha, fz, tyre: TyreParameters, *, scale: float = 1.0, mirrored: bool = False):
    """Pneumatic trail ``t`` (m) under combined slip, eq. 4.E33-4.E44 and 4.E73-4.E78 at gamma = 0.

    At pure slip (``kappa = 0``) it is the trail of eq. 4.E33; a slip ratio
    lowers it through the equivalent slip ``alpha_eq``, built here as
    ``alpha sqrt(1 + (K_xk / K_ya)^2 kappa^2 / (alpha^2 + eps^2))``: equal to
    ``alpha`` at pure slip and to ``sgn(alpha) sqrt(alpha^2 + (K_xk / K_ya)^2
    kappa^2)`` of eq. 4.E77 beyond the smoothing width, without the kink of a sign.
    """
    dfz = load_increment(fz, tyre)
    fz0 = tyre.nominal_load
    b = (tyre.QBZ1 + tyre.QBZ2 * dfz + tyre.QBZ3 * dfz**2) * scale / tyre.friction_scale
    c = tyre.QCZ1
    d = fz * tyre.unloaded_radius / fz0 * (tyre.QDZ1 + tyre.QDZ2 * dfz)
    side = -1.0 if mirrored else 1.0
    e = (tyre.QEZ1 + tyre.QEZ2 * dfz + tyre.QEZ3 * dfz**2) * (1 + tyre.QEZ4 * (2 / ca.pi) * ca.atan(b * c * side * alpha))
    stiffness_ratio = longitudinal_slip_stiffness(fz, tyre) / (-cornering_stiffness(fz, tyre, scale) + _EPS_FORCE)
    width = SIGN_SMOOTHING_SLIP**2
    alpha_eq = alpha * ca.sqrt(1 + (stiffness_ratio * kappa) ** 2 / (alpha * alpha + width))
    # cos'(alpha) = V_cx / V_c, with alpha the slip tan(alpha)
    return _weight(b, c, e, alpha_eq) * d / ca.sqrt(1 + alpha * alpha)


def aligning_moment(kappa, alpha, fz, tyre: TyreParameters, *, scale: float = 1.0, mirrored: bool = False,
                    lateral_force=None):
    """Self-aligning moment ``M_z = -t F_y`` (N m, ISO: positive about z up), eq. 4.E31 and 4.E71.

    Parameters are those of :func:`combined_forces`; ``lateral_force`` is its
    ``F_y`` when already at hand. For small slip the moment turns the wheel
    towards its direction of travel: a positive slip (contact point moving to
    the wheel's left) gives a negative force and a positive moment.
    """
    if lateral_force is None:
        lateral_force = combined_forces(kappa, alpha, fz, tyre, scale=scale, mirrored=mirrored)[1]
    return -pneumatic_trail(kappa, alpha, fz, tyre, scale=scale, mirrored=mirrored) * lateral_force
