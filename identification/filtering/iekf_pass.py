"""One pass of the Identifying EKF over a record: the filter step in CasADi and its compiled loop.

The augmented state is ``z = [x; theta]`` (Best & Bogdanski 2017, eq. 7-8); ``P`` is carried as the
nonzeros of its upper triangle (``casadi.Sparsity.upper`` order), symmetric by construction. The
``paper`` covariance form (eq. 11-14) can lose positive definiteness and is kept to reproduce the paper;
``joseph`` (default) updates with ``P - K V' - V K'``, ``V = P H' - K S / 2`` (the Joseph form at a third
of its cost) and predicts with ``Phi P Phi' + T Q``, ``Phi`` the exact transition Jacobian, which keeps
``P`` positive definite.

The pass is CasADi-generated C looped by a small C driver in the same library. A large step (the
spline-nonlinear model) generates only the model and its Jacobians, the covariance algebra running as
C loops (:mod:`vehid.identification.filtering.iekf_kernel`). Without a C compiler the step runs in CasADi's virtual
machine under ``mapaccum``.
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import warnings
from dataclasses import dataclass
from typing import Callable

import casadi as ca
import numpy as np

from ..compiled import NoCompilerWarning, compile_driver, find_c_compiler
from ..choices import COVARIANCE_FORMS
from ..errors import DivergenceError
from ..models.transition import check_discretization
from .filter_models import FilterModel
from .iekf_kernel import structured_pass_source

__all__ = [
    "COVARIANCE_FORMS",
    "KERNELS",
    "PASS_DRIVER",
    "CompiledPass",
    "FilterStep",
    "build_filter_step",
    "compiled_pass",
    "numpy_reference_pass",
    "pack_covariance",
    "unpack_covariance",
]

KERNELS = ("auto", "structured", "generated")

# Flags and threshold chosen by measurement (docs/iekf_tuning.md, benchmarks/iekf_compile_levels.py); the
# library is cached per CPU. The structured loops compile in about 2 s at any size; the generated step's
# compile grows with its instructions (measured 3 s at 5,000, 6.5 s at 7,000, 14 s at 13,000) while its pass
# stays 1.6-2.4x faster. Up to 10,000 the extra compile is repaid within a few hundred passes of a run;
# beyond, by thousands, which a run never makes.
PASS_COMPILE_FLAGS = "-O3 -march=native"
LARGE_STEP_INSTRUCTIONS = 10_000
LARGE_STEP_COMPILE_FLAGS = "-O1"
# A full-vehicle model's step (the 23-state car with six parameters: 160,000 instructions) makes loops whose
# model part alone took over 3 min of CPU to compile at -O3 and 20 s at -O1, for a pass about twice as slow:
# -O1 is taken beyond this size for a filter model whose step integrates a physical model (its attribute
# ``model_bound_step``). The modal and spline filters' loops compile in seconds at -O3, and their passes
# at -O1 made the handling study 60 % slower, so they keep the full optimisation whatever their size.
HUGE_STEP_INSTRUCTIONS = 100_000
# A short run does not repay a full optimisation. Against -O3 -march=native the generated step at -O0
# compiles 0.2-0.7 ms of CPU faster per instruction and runs 0.6-1.5 ns slower per instruction and
# sample (benchmarks/iekf_compile_levels.py, 900 to 13,000 instructions, two runs): both grow with the
# step, so the break-even, 150,000 to 1,200,000 filter steps (samples x passes), hardly depends on its
# size. The lowest figure is that of the smallest step, whose whole compile takes under half a second:
# at 250,000 steps the quick build loses at most a tenth of a second there and wins everywhere else.
# Only the rounding differs (no fused multiply-adds at -O0).
QUICK_COMPILE_FLAGS = "-O0"
QUICK_COMPILE_STEPS = 250_000


@functools.lru_cache(maxsize=64)
def _upper_triangle(m: int) -> tuple[np.ndarray, np.ndarray]:
    """Row and column indices of an m x m upper triangle, column-major (asked for at every pass: kept)."""
    rows, cols = np.triu_indices(m)
    order = np.lexsort((rows, cols))
    rows, cols = rows[order], cols[order]
    rows.setflags(write=False)
    cols.setflags(write=False)
    return rows, cols


def pack_covariance(P: np.ndarray) -> np.ndarray:
    """Upper-triangle nonzeros of a symmetric matrix, column-major (casadi.Sparsity.upper order)."""
    rows, cols = _upper_triangle(P.shape[0])
    return np.asarray(P)[rows, cols].copy()


def unpack_covariance(values: np.ndarray, m: int) -> np.ndarray:
    """Inverse of :func:`pack_covariance`: the full symmetric matrix."""
    rows, cols = _upper_triangle(m)
    P = np.zeros((m, m))
    P[rows, cols] = values
    P[cols, rows] = values
    return P


@dataclass(frozen=True)
class FilterStep:
    """The symbolic filter step and the pieces the NumPy reference needs.

    ``step(s, u0, u1, y, q, r, c) -> (s_next, innovation)`` where
    ``s = [z; vech_upper(P)]`` and ``c`` the model's constants (for example
    spline node ranges, which change between passes without recompiling);
    ``model(z, u0, u1, c) -> (z_next, Phi, h, H)`` evaluates the model and
    its exact Jacobians alone; both at the sample time ``dt``.
    ``timed_step`` and ``timed_model`` are the same with the sample time as a
    last input ``dt``: the compiled pass is generated from these, so that one
    library serves every record of a structure whatever its sample time.
    """

    n_z: int
    n_states: int
    n_u: int
    n_y: int
    n_c: int
    dt: float
    discretization: str
    covariance: str
    timed_step: ca.Function
    timed_model: ca.Function

    # Built when first asked for: the compiled pass is generated from the timed functions alone, and
    # substituting the sample time into a physical model's large expression graph costs seconds per
    # structure (about two thirds of a 23-state car's symbolic build) that only the virtual machine's
    # pass and the NumPy reference use.
    @functools.cached_property
    def step(self) -> ca.Function:
        return _at_sample_time(self.timed_step, self.dt)

    @functools.cached_property
    def model(self) -> ca.Function:
        return _at_sample_time(self.timed_model, self.dt)

    @property
    def n_state(self) -> int:
        """Length of the packed filter state ``[z; upper(P)]``."""
        return self.n_z + self.n_z * (self.n_z + 1) // 2


@functools.lru_cache(maxsize=32)
def _timed_functions(filter_model: FilterModel, discretization: str, covariance: str) -> tuple[ca.Function, ca.Function]:
    """The model and the filter step with the sample time a symbolic input ``dt`` (their last)."""
    n_states, n_theta, n_u, n_y = filter_model.n_states, filter_model.n_theta, filter_model.n_u, filter_model.n_y
    n_c = filter_model.n_constants
    m = n_states + n_theta

    # The model and its Jacobians, as a function of a free augmented state.
    z = ca.SX.sym("z", m)
    u0 = ca.SX.sym("u0", n_u)
    u1 = ca.SX.sym("u1", n_u)
    c = ca.SX.sym("c", n_c)
    dt = ca.SX.sym("dt")
    x, theta = z[:n_states], z[n_states:]
    x_next = filter_model.transition(x, theta, u0, u1, dt, discretization, c)
    z_next = ca.vertcat(x_next, theta)
    h = filter_model.output(x, theta, u0, c)
    model = ca.Function(
        "iekf_model",
        [z, u0, u1, c, dt],
        [z_next, ca.jacobian(z_next, z), h, ca.jacobian(h, z)],
        ["z", "u0", "u1", "c", "dt"],
        ["z_next", "Phi", "h", "H"],
    )

    upper = ca.Sparsity.upper(m)
    s = ca.SX.sym("s", m + upper.nnz())
    y = ca.SX.sym("y", n_y)
    q = ca.SX.sym("q", m)
    r = ca.SX.sym("r", n_y, n_y)
    zk = s[:m]
    P = ca.triu2symm(ca.SX(upper, s[m:]))
    _, _, h_k, H = model(zk, u0, u1, c, dt)
    innovation = y - h_k
    W = ca.mtimes(P, H.T)
    S = ca.mtimes(H, W) + r
    K = ca.mtimes(W, ca.inv(S)) if n_y > 1 else W / S
    if covariance == "paper":
        z_pred, Phi, _, _ = model(zk, u0, u1, c, dt)
        P_updated = P - ca.mtimes(K, W.T)
        F_dt = Phi - ca.SX.eye(m)  # T F of eq. 13
        P_next = P_updated + ca.mtimes(F_dt, P_updated) + ca.mtimes(P_updated, F_dt.T) + dt * ca.diag(q)
        z_out = z_pred + ca.mtimes(K, innovation)
    else:
        V = W - 0.5 * ca.mtimes(K, S)
        P_updated = P - ca.mtimes(K, V.T) - ca.mtimes(V, K.T)
        z_post = zk + ca.mtimes(K, innovation)
        z_out, Phi, _, _ = model(z_post, u0, u1, c, dt)
        P_next = ca.mtimes(ca.mtimes(Phi, P_updated), Phi.T) + dt * ca.diag(q)
    P_next_upper = ca.vertcat(*[P_next[i, j] for j in range(m) for i in range(j + 1)])
    step = ca.Function(
        "iekf_step",
        [s, u0, u1, y, q, r, c, dt],
        [ca.vertcat(z_out, P_next_upper), innovation],
        ["s", "u0", "u1", "y", "q", "r", "c", "dt"],
        ["s_next", "innovation"],
        {"cse": True},
    )
    return step, model


def _at_sample_time(timed: ca.Function, dt: float) -> ca.Function:
    """``timed`` with its last input, the sample time, fixed at ``dt``."""
    inputs = [ca.SX.sym(timed.name_in(i), timed.sparsity_in(i)) for i in range(timed.n_in() - 1)]
    outputs = timed(*inputs, dt)
    outputs = list(outputs) if isinstance(outputs, (tuple, list)) else [outputs]
    return ca.Function(timed.name(), inputs, outputs, timed.name_in()[:-1], timed.name_out(), {"cse": True})


def build_filter_step(filter_model: FilterModel, dt: float, discretization: str, covariance: str) -> FilterStep:
    """Build the SX filter step for a filter model (see :mod:`vehid.identification.filtering.filter_models`)."""
    check_discretization(discretization)
    if covariance not in COVARIANCE_FORMS:
        raise ValueError(f"unknown covariance form {covariance!r}; use one of {', '.join(COVARIANCE_FORMS)}")
    timed_step, timed_model = _timed_functions(filter_model, discretization, covariance)
    m = filter_model.n_states + filter_model.n_theta
    return FilterStep(
        m, filter_model.n_states,
        filter_model.n_u, filter_model.n_y, filter_model.n_constants, float(dt), discretization, covariance,
        timed_step, timed_model,
    )


#: The C source of the pass driver around the generated step (the compile-level benchmark builds it with other flags).
PASS_DRIVER = r"""
/* The pass driver: calls the generated step once per sample with the filter
   state in two alternating buffers (generated code must not alias inputs and
   outputs). u, y and innovations are time-major. */
#include <stdlib.h>
#include <string.h>
int vehid_iekf_pass(long long int n_samples, long long int n_u, long long int n_y,
                    long long int n_state, const double* u, const double* y,
                    const double* q, const double* r, const double* c, const double* dt,
                    double* state, double* innovations) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  STEP_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real** arg = malloc(sizeof(casadi_real*) * (sz_arg > 8 ? sz_arg : 8));
  casadi_real** res = malloc(sizeof(casadi_real*) * (sz_res > 2 ? sz_res : 2));
  casadi_int* iw = malloc(sizeof(casadi_int) * (sz_iw > 0 ? sz_iw : 1));
  casadi_real* w = malloc(sizeof(casadi_real) * (sz_w > 0 ? sz_w : 1));
  double* other = malloc(sizeof(double) * n_state);
  if (!arg || !res || !iw || !w || !other) return -1;
  double* current = state;
  double* next = other;
  long long int k;
  int status = 0;
  for (k = 0; k < n_samples; ++k) {
    arg[0] = current;
    arg[1] = u + k * n_u;
    arg[2] = u + (k + 1 < n_samples ? k + 1 : k) * n_u;
    arg[3] = y + k * n_y;
    arg[4] = q;
    arg[5] = r;
    arg[6] = c;
    arg[7] = dt;
    res[0] = next;
    res[1] = innovations + k * n_y;
    /* A failed step reports the sample it failed at (1-based), so the caller never takes a half-advanced state for a finished pass. */
    if (STEP(arg, res, iw, w, 0)) { status = k < 2147483646LL ? (int)(k + 1) : 2147483647; break; }
    double* swap = current; current = next; next = swap;
  }
  if (current != state) memcpy(state, current, sizeof(double) * n_state);
  free(arg); free(res); free(iw); free(w); free(other);
  return status;
}
"""


def _constants(filter_step: FilterStep, c: np.ndarray | None) -> np.ndarray:
    c = np.zeros(0) if c is None else np.ascontiguousarray(c, dtype=float).ravel()
    if c.size != filter_step.n_c:
        raise ValueError(f"the model takes {filter_step.n_c} constants; got {c.size}")
    return c


class CompiledPass:
    """A loaded pass library: ``run(state, u, y, q, r, c=None) -> (state, innovations)``."""

    def __init__(self, function: Callable[..., int], filter_step: FilterStep):
        self._function = function
        self.filter_step = filter_step

    def __call__(self, state: np.ndarray, u: np.ndarray, y: np.ndarray, q: np.ndarray, r: np.ndarray, c: np.ndarray | None = None):
        fs = self.filter_step
        c = _constants(fs, c)
        state = np.ascontiguousarray(state, dtype=float).copy()
        u = np.ascontiguousarray(u, dtype=float)
        y = np.ascontiguousarray(y, dtype=float)
        q = np.ascontiguousarray(q, dtype=float)
        r = np.ascontiguousarray(np.asarray(r, dtype=float).T)  # CasADi is column-major
        n = y.shape[0]
        innovations = np.empty((n, fs.n_y))
        as_p = lambda a: a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))  # noqa: E731
        status = self._function(
            n, fs.n_u, fs.n_y, state.size, as_p(u), as_p(y), as_p(q), as_p(r),
            as_p(c if c.size else np.zeros(1)),  # a valid pointer even where the model has no constants
            as_p(np.array([fs.dt])), as_p(state), as_p(innovations),
        )
        if status < 0:
            raise MemoryError("the compiled IEKF pass could not allocate its work arrays")
        if status > 0:
            raise DivergenceError(f"the compiled filter step failed at sample {status - 1} of {n}")
        return state, innovations


class _VirtualMachinePass:
    """The same pass under CasADi's virtual machine (no C compiler)."""

    def __init__(self, filter_step: FilterStep):
        self.filter_step = filter_step

    def __call__(self, state, u, y, q, r, c=None):
        n = y.shape[0]
        c = _constants(self.filter_step, c)
        lifted = self.filter_step.step.mapaccum("iekf_pass_vm", n)
        u_next = np.vstack([u[1:], u[-1:]])
        s_all, innovations = lifted(state, u.T, u_next.T, y.T, q, np.asarray(r, dtype=float), c)
        return np.asarray(s_all)[:, -1].copy(), np.asarray(innovations).T


@functools.lru_cache(maxsize=32)
def _compiled_library(filter_model: FilterModel, discretization: str, covariance: str, kernel: str, quick: bool):
    """The loaded pass of a structure, its sample time a run-time argument: compiled once per structure
    (and per build: ``quick`` for a run too short to repay the full optimisation of the generated step)."""
    timed_step, _ = _timed_functions(filter_model, discretization, covariance)
    tag = hashlib.sha256(filter_model.cache_key().encode()).hexdigest()[:8]
    large = timed_step.n_instructions() > LARGE_STEP_INSTRUCTIONS
    if kernel == "structured" or (kernel == "auto" and large):
        source, functions = structured_pass_source(build_filter_step(filter_model, 1.0, discretization, covariance))
        huge = (getattr(filter_model, "model_bound_step", False)
                and timed_step.n_instructions() > HUGE_STEP_INSTRUCTIONS)
        return compile_driver(
            tuple(functions), source, library_name=f"iekf_loops_{tag}", entry="vehid_iekf_pass",
            n_integers=4, n_arrays=8, optimisation=LARGE_STEP_COMPILE_FLAGS if huge else PASS_COMPILE_FLAGS,
        )
    if quick:
        flags = QUICK_COMPILE_FLAGS
    else:
        flags = LARGE_STEP_COMPILE_FLAGS if large else PASS_COMPILE_FLAGS
    return compile_driver(
        timed_step, PASS_DRIVER, library_name=f"iekf_pass_{tag}", entry="vehid_iekf_pass",
        n_integers=4, n_arrays=8, optimisation=flags,
    )


@functools.lru_cache(maxsize=32)
def _pass_for(filter_model: FilterModel, dt: float, discretization: str, covariance: str, kernel: str, quick: bool):
    filter_step = build_filter_step(filter_model, dt, discretization, covariance)
    if find_c_compiler() is None:
        warnings.warn(
            "no C compiler found: the IEKF pass runs in CasADi's virtual machine "
            "(install gcc or set CC for compiled speed)",
            NoCompilerWarning,
            stacklevel=3,
        )
        return _VirtualMachinePass(filter_step)
    return CompiledPass(_compiled_library(filter_model, discretization, covariance, kernel, quick), filter_step)


def compiled_pass(filter_model: FilterModel, dt: float, discretization: str, covariance: str, kernel: str = "auto",
                  *, expected_steps: int | None = None):
    """The pass function for a filter model, built and compiled once (cached in memory and on disk).

    ``kernel`` chooses the compiled code: ``structured`` generates only the
    model and its Jacobians and runs the covariance algebra as C loops with
    the low-rank prediction (:mod:`vehid.identification.filtering.iekf_kernel`);
    ``generated`` compiles the whole SX step; ``auto`` (default) takes the
    loops where the generated step is large (above
    ``LARGE_STEP_INSTRUCTIONS``), which pays only for large steps (docs/iekf_tuning.md).

    ``expected_steps`` is the most filter steps the caller will run (samples
    times passes); at most ``QUICK_COMPILE_STEPS`` the generated step is built
    at ``QUICK_COMPILE_FLAGS``, which costs less than a full optimisation repays
    over so few steps. ``None`` (unknown) builds it fully optimised.

    Returns a callable ``run(state, u, y, q, r, c=None) -> (state, innovations)`` with
    ``state = [z; upper(P)]`` (see :func:`pack_covariance`), ``u`` (N, n_u),
    ``y`` (N, n_y), ``q`` (m,) the diagonal of Q, ``r`` (n_y, n_y), ``c`` the
    model's constants (none for a linear model).
    Its attribute ``filter_step`` is the :class:`FilterStep`.
    """
    if kernel not in KERNELS:
        raise ValueError(f"unknown kernel {kernel!r}; use one of {', '.join(KERNELS)}")
    quick = expected_steps is not None and expected_steps <= QUICK_COMPILE_STEPS
    return _pass_for(filter_model, float(dt), discretization, covariance, kernel, quick)


def numpy_reference_pass(
    filter_step: FilterStep,
    state: np.ndarray,
    u: np.ndarray,
    y: np.ndarray,
    q: np.ndarray,
    r: np.ndarray,
    c: np.ndarray | None = None,
):
    """The same pass written plainly: a Python loop, full matrices, textbook forms.

    The model and its Jacobians come from ``filter_step.model`` (CasADi's
    virtual machine); the filter algebra is NumPy: the paper's eq. 11-14, or
    the Joseph product form ``(I - K H) P (I - K H)' + K R K'`` followed by
    ``Phi P Phi' + T Q``. The reference for tests and the benchmark's baseline.
    """
    fs = filter_step
    c = _constants(fs, c)
    m = fs.n_z
    z = np.array(state[:m], dtype=float)
    P = unpack_covariance(np.asarray(state[m:], dtype=float), m)
    Q = np.diag(q)
    R = np.atleast_2d(np.asarray(r, dtype=float))
    identity = np.eye(m)
    n = y.shape[0]
    innovations = np.empty((n, fs.n_y))
    model = fs.model
    for k in range(n):
        u0 = u[k]
        u1 = u[k + 1] if k + 1 < n else u[k]
        z_pred, Phi, h, H = (np.asarray(v) for v in model(z, u0, u1, c))
        h = h.ravel()
        e = y[k] - h
        innovations[k] = e
        S = H @ P @ H.T + R
        K = np.linalg.solve(S.T, (P @ H.T).T).T
        if fs.covariance == "paper":
            P = (identity - K @ H) @ P
            F_dt = Phi - identity
            P = P + F_dt @ P + P @ F_dt.T + fs.dt * Q
            z = z_pred.ravel() + K @ e
        else:
            J = identity - K @ H
            P = J @ P @ J.T + K @ R @ K.T
            z_post = z + K @ e
            z_next, Phi, _, _ = (np.asarray(v) for v in model(z_post, u0, u1, c))
            P = Phi @ P @ Phi.T + fs.dt * Q
            z = z_next.ravel()
        P = 0.5 * (P + P.T)
    return np.concatenate([z, pack_covariance(P)]), innovations
