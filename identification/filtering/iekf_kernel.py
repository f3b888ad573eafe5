"""The IEKF pass with the covariance algebra written as C loops around two small generated functions.

Unrolled, the ``m^2`` covariance terms dominate a large filter step. Here CasADi generates only the
model-specific ``measure(z, u0, c) -> (h, H)`` and ``predict(z, u0, u1, c) -> (x_next, E)``,
``E = Phi[:n_states, :] - [I 0]``, both as nonzeros row by row. The parameters have no dynamics, so the
congruence is the low-rank update ``Phi P Phi' = P + G + G' + E G'``, ``G = E P``: ``O(n_states m nnz(E))``
work instead of ``O(m^3)``. The update is the Joseph identity of :mod:`vehid.identification.filtering.iekf_pass` on the
packed upper triangle, column by column (contiguous, so vectorised); ``S`` is inverted by Gauss-Jordan
elimination with partial pivoting. The sparsity patterns are constant tables in the C source, so the
library's cache key names the model exactly.
"""

from __future__ import annotations

from typing import Any

import casadi as ca

__all__ = ["structured_pass_source", "model_functions"]


def _row_major_nonzeros(matrix: Any, minus_identity_rows: int = 0) -> tuple[list[Any], list[int], list[int]]:
    """Nonzeros of an SX matrix row by row: (values, row pointers, column indices).

    With ``minus_identity_rows`` > 0 the diagonal of the first rows joins the
    pattern and 1 is subtracted there (``E = Phi - I`` on the state rows).
    """
    rows, cols = matrix.sparsity().get_triplet()
    entries = set(zip(rows, cols))
    entries |= {(i, i) for i in range(minus_identity_rows)}
    ordered = sorted(entries)
    values, pointers, columns = [], [0] * (matrix.size1() + 1), []
    for row, col in ordered:
        value = matrix[row, col]
        if row == col and row < minus_identity_rows:
            value = value - 1.0
        values.append(value)
        columns.append(col)
        pointers[row + 1] += 1
    for row in range(matrix.size1()):
        pointers[row + 1] += pointers[row]
    return values, pointers, columns


def model_functions(filter_step: Any) -> tuple[ca.Function, ca.Function, dict[str, list[int]]]:
    """The generated pieces of the structured pass and the sparsity tables the C loops use.

    From a :class:`~identification.filtering.iekf_pass.FilterStep`'s model function;
    returns ``(measure, predict, tables)`` with ``tables`` holding
    ``h_pointers``, ``h_columns`` (rows of ``H``) and ``e_pointers``,
    ``e_columns`` (the state rows of ``E = Phi - I``).
    """
    fs = filter_step
    z, u0, u1, c = (ca.SX.sym(name, size) for name, size in (("z", fs.n_z), ("u0", fs.n_u), ("u1", fs.n_u), ("c", fs.n_c)))
    dt = ca.SX.sym("dt")
    z_next, Phi, h, H = fs.timed_model(z, u0, u1, c, dt)
    h_values, h_pointers, h_columns = _row_major_nonzeros(H)
    e_values, e_pointers, e_columns = _row_major_nonzeros(Phi[: fs.n_states, :], minus_identity_rows=fs.n_states)
    measure = ca.Function("iekf_measure", [z, u0, c], [h, ca.vertcat(*h_values)], ["z", "u0", "c"], ["h", "H_nz"],
                          {"cse": True})
    # The sample time is an input, so that one library serves every sample time.
    predict = ca.Function("iekf_predict", [z, u0, u1, c, dt], [z_next[: fs.n_states], ca.vertcat(*e_values)],
                          ["z", "u0", "u1", "c", "dt"], ["x_next", "E_nz"], {"cse": True})
    tables = {"h_pointers": h_pointers, "h_columns": h_columns, "e_pointers": e_pointers, "e_columns": e_columns}
    return measure, predict, tables


def _table(name: str, values: list[int]) -> str:
    body = ", ".join(str(v) for v in values) if values else "0"
    return f"static const long long {name}[] = {{{body}}};\n"


_LOOPS = r"""
/* Packed upper triangle, column-major: entry (i, j), i <= j, at j (j + 1) / 2 + i. */
#include <stdlib.h>
#include <string.h>
#define UP(i, j) ((j) * ((j) + 1) / 2 + (i))
#define SYM(P, i, j) ((i) <= (j) ? (P)[UP(i, j)] : (P)[UP(j, i)])

static int vehid_work_size(casadi_int* sz_arg, casadi_int* sz_res, casadi_int* sz_iw, casadi_int* sz_w) {
  casadi_int a, r, i, w;
  iekf_measure_work(sz_arg, sz_res, sz_iw, sz_w);
  iekf_predict_work(&a, &r, &i, &w);
  if (a > *sz_arg) *sz_arg = a;
  if (r > *sz_res) *sz_res = r;
  if (i > *sz_iw) *sz_iw = i;
  if (w > *sz_w) *sz_w = w;
  if (*sz_arg < 5) *sz_arg = 5;
  if (*sz_res < 2) *sz_res = 2;
  return 0;
}

/* Inverse of the n x n matrix A (column-major, overwritten) by Gauss-Jordan with partial pivoting. */
static void vehid_invert(long long n, double* A, double* inverse) {
  long long i, j, k;
  for (j = 0; j < n; ++j) for (i = 0; i < n; ++i) inverse[i + j * n] = (i == j);
  for (k = 0; k < n; ++k) {
    long long pivot = k;
    for (i = k + 1; i < n; ++i) if (fabs(A[i + k * n]) > fabs(A[pivot + k * n])) pivot = i;
    if (pivot != k) {
      for (j = 0; j < n; ++j) {
        double t = A[k + j * n]; A[k + j * n] = A[pivot + j * n]; A[pivot + j * n] = t;
        t = inverse[k + j * n]; inverse[k + j * n] = inverse[pivot + j * n]; inverse[pivot + j * n] = t;
      }
    }
    double d = A[k + k * n];
    for (j = 0; j < n; ++j) { A[k + j * n] /= d; inverse[k + j * n] /= d; }
    for (i = 0; i < n; ++i) {
      if (i == k) continue;
      double f = A[i + k * n];
      if (f == 0.0) continue;
      for (j = 0; j < n; ++j) { A[i + j * n] -= f * A[k + j * n]; inverse[i + j * n] -= f * inverse[k + j * n]; }
    }
  }
}

/* sum over t in [first, last) of values[t] * column[index[t]], in four partial sums so that the
   additions do not wait on each other */
static inline double sparse_dot(const double* column, const long long* index, const double* values,
                                long long first, long long last) {
  double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
  long long t = first;
  for (; t + 3 < last; t += 4) {
    s0 += values[t] * column[index[t]];
    s1 += values[t + 1] * column[index[t + 1]];
    s2 += values[t + 2] * column[index[t + 2]];
    s3 += values[t + 3] * column[index[t + 3]];
  }
  for (; t < last; ++t) s0 += values[t] * column[index[t]];
  return (s0 + s1) + (s2 + s3);
}

int vehid_iekf_pass(long long int n_samples, long long int n_u, long long int n_y,
                    long long int n_state, const double* u, const double* y,
                    const double* q, const double* r, const double* c, const double* dt,
                    double* state, double* innovations) {
  const long long m = N_Z, nx = N_X;
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  vehid_work_size(&sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real** arg = malloc(sizeof(casadi_real*) * sz_arg);
  casadi_real** res = malloc(sizeof(casadi_real*) * sz_res);
  casadi_int* iw = malloc(sizeof(casadi_int) * (sz_iw > 0 ? sz_iw : 1));
  casadi_real* w = malloc(sizeof(casadi_real) * (sz_w > 0 ? sz_w : 1));
  double* h = malloc(sizeof(double) * n_y);
  double* Hnz = malloc(sizeof(double) * (NNZ_H > 0 ? NNZ_H : 1));
  double* Enz = malloc(sizeof(double) * (NNZ_E > 0 ? NNZ_E : 1));
  double* x_next = malloc(sizeof(double) * (nx > 0 ? nx : 1));
  double* W = malloc(sizeof(double) * m * n_y);
  double* K = malloc(sizeof(double) * m * n_y);
  double* V = malloc(sizeof(double) * m * n_y);
  double* S = malloc(sizeof(double) * n_y * n_y);
  double* S_work = malloc(sizeof(double) * n_y * n_y);
  double* S_inverse = malloc(sizeof(double) * n_y * n_y);
  double* G = malloc(sizeof(double) * (nx > 0 ? nx : 1) * m);
  double* e = malloc(sizeof(double) * n_y);
  if (!arg || !res || !iw || !w || !h || !Hnz || !Enz || !x_next || !W || !K || !V || !S || !S_work
      || !S_inverse || !G || !e) return -1;
  long long h_end[N_Y], e_end[N_X > 0 ? N_X : 1];
  double* z = state;
  double* P = state + m;
  int status = 0;
  long long k, i, j, a, b, s, t, o;
  for (k = 0; k < n_samples && !status; ++k) {
    const double* u0 = u + k * n_u;
    const double* u1 = u + (k + 1 < n_samples ? k + 1 : k) * n_u;
    /* measurement: h, H at the prior state */
    arg[0] = z; arg[1] = u0; arg[2] = c;
    res[0] = h; res[1] = Hnz;
    if (iekf_measure(arg, res, iw, w, 0)) { status = k < 2147483646LL ? (int)(k + 1) : 2147483647; break; }
    for (o = 0; o < n_y; ++o) { e[o] = y[k * n_y + o] - h[o]; innovations[k * n_y + o] = e[o]; }
    /* W = P H' (m x n_y, column-major), S = H W + R. P(i, l) lies in column l for i <= l and in
       column i for i > l: both parts read whole columns, never a strided row */
    memset(W, 0, sizeof(double) * m * n_y);
    for (o = 0; o < n_y; ++o) {
      double* Wo = W + o * m;
      for (t = H_POINTERS[o]; t < H_POINTERS[o + 1]; ++t) {
        long long l = H_COLUMNS[t];
        double hv = Hnz[t];
        const double* column = P + UP(0, l);
        for (i = 0; i <= l; ++i) Wo[i] += column[i] * hv;
      }
    }
    for (o = 0; o < N_Y; ++o) h_end[o] = H_POINTERS[o];
    for (i = 1; i < m; ++i) {
      const double* column = P + UP(0, i);
      for (o = 0; o < N_Y; ++o) {
        while (h_end[o] < H_POINTERS[o + 1] && H_COLUMNS[h_end[o]] < i) ++h_end[o];
        W[o * m + i] += sparse_dot(column, H_COLUMNS, Hnz, H_POINTERS[o], h_end[o]);
      }
    }
    for (s = 0; s < n_y; ++s) {
      for (o = 0; o < n_y; ++o) {
        double v = r[o + s * n_y];
        for (t = H_POINTERS[o]; t < H_POINTERS[o + 1]; ++t) v += Hnz[t] * W[s * m + H_COLUMNS[t]];
        S[o + s * n_y] = v;
      }
    }
    /* K = W S^-1, V = W - K S / 2 */
    if (n_y == 1) {
      for (i = 0; i < m; ++i) K[i] = W[i] / S[0];
    } else {
      memcpy(S_work, S, sizeof(double) * n_y * n_y);
      vehid_invert(n_y, S_work, S_inverse);
      for (o = 0; o < n_y; ++o) {
        double* Ko = K + o * m;
        for (i = 0; i < m; ++i) Ko[i] = 0.0;
        for (s = 0; s < n_y; ++s) {
          double f = S_inverse[s + o * n_y];
          const double* Ws = W + s * m;
          for (i = 0; i < m; ++i) Ko[i] += Ws[i] * f;
        }
      }
    }
#if PAPER_FORM
    /* P <- (I - K H) P = P - K W' (upper triangle) */
    for (j = 0; j < m; ++j) {
      double* column = P + UP(0, j);
      for (o = 0; o < n_y; ++o) {
        const double* Ko = K + o * m;
        double f = W[o * m + j];
        for (i = 0; i <= j; ++i) column[i] -= Ko[i] * f;
      }
    }
    /* z <- phi(z) + K e, prediction at the prior state */
    arg[0] = z; arg[1] = u0; arg[2] = u1; arg[3] = c; arg[4] = dt;
    res[0] = x_next; res[1] = Enz;
    if (iekf_predict(arg, res, iw, w, 0)) { status = k < 2147483646LL ? (int)(k + 1) : 2147483647; break; }
    for (i = 0; i < nx; ++i) z[i] = x_next[i];
    for (o = 0; o < n_y; ++o) for (i = 0; i < m; ++i) z[i] += K[o * m + i] * e[o];
#else
    for (o = 0; o < n_y; ++o) {
      double* Vo = V + o * m;
      for (i = 0; i < m; ++i) Vo[i] = W[o * m + i];
      for (s = 0; s < n_y; ++s) {
        double f = 0.5 * S[s + o * n_y];
        const double* Ks = K + s * m;
        for (i = 0; i < m; ++i) Vo[i] -= Ks[i] * f;
      }
    }
    /* Joseph identity: P <- P - K V' - V K' (upper triangle); the outputs fused in the
       inner loop (N_Y is a compile-time constant), so each column is read and written once */
    for (j = 0; j < m; ++j) {
      double* column = P + UP(0, j);
      double kj[N_Y], vj[N_Y];
      for (o = 0; o < N_Y; ++o) { kj[o] = K[o * m + j]; vj[o] = V[o * m + j]; }
      for (i = 0; i <= j; ++i) {
        double d = 0.0;
        for (o = 0; o < N_Y; ++o) d += K[o * m + i] * vj[o] + V[o * m + i] * kj[o];
        column[i] -= d;
      }
    }
    /* z+ = z + K e, then the prediction at z+ */
    for (o = 0; o < n_y; ++o) for (i = 0; i < m; ++i) z[i] += K[o * m + i] * e[o];
    arg[0] = z; arg[1] = u0; arg[2] = u1; arg[3] = c; arg[4] = dt;
    res[0] = x_next; res[1] = Enz;
    if (iekf_predict(arg, res, iw, w, 0)) { status = k < 2147483646LL ? (int)(k + 1) : 2147483647; break; }
    for (i = 0; i < nx; ++i) z[i] = x_next[i];
#endif
    /* Phi P Phi' with Phi = I + E (E nonzero in the state rows only): G = E P, then
       P + G + G' (+ E G' in the congruence form) on the state rows and columns */
    for (a = 0; a < nx; ++a) {  /* P(l, j) in column l for j < l, in column j for j >= l (as for W) */
      double* Ga = G + a * m;
      for (j = 0; j < m; ++j) Ga[j] = 0.0;
      for (t = E_POINTERS[a]; t < E_POINTERS[a + 1]; ++t) {
        long long l = E_COLUMNS[t];
        double ev = Enz[t];
        const double* column = P + UP(0, l);
        for (j = 0; j < l; ++j) Ga[j] += ev * column[j];
      }
    }
    for (a = 0; a < N_X; ++a) e_end[a] = E_POINTERS[a];
    for (j = 0; j < m; ++j) {
      const double* column = P + UP(0, j);
      for (a = 0; a < N_X; ++a) {
        while (e_end[a] < E_POINTERS[a + 1] && E_COLUMNS[e_end[a]] <= j) ++e_end[a];
        G[a * m + j] += sparse_dot(column, E_COLUMNS, Enz, E_POINTERS[a], e_end[a]);
      }
    }
    for (a = 0; a < nx; ++a) {
      for (j = nx; j < m; ++j) P[UP(a, j)] += G[a * m + j];
      for (b = a; b < nx; ++b) {
        double v = G[a * m + b] + G[b * m + a];
#if !PAPER_FORM
        for (t = E_POINTERS[a]; t < E_POINTERS[a + 1]; ++t) v += Enz[t] * G[b * m + E_COLUMNS[t]];
#endif
        P[UP(a, b)] += v;
      }
    }
    for (i = 0; i < m; ++i) P[UP(i, i)] += dt[0] * q[i];
  }
  free(arg); free(res); free(iw); free(w); free(h); free(Hnz); free(Enz); free(x_next); free(W); free(K);
  free(V); free(S); free(S_work); free(S_inverse); free(G); free(e);
  return status;
}
"""


def structured_pass_source(filter_step: Any) -> tuple[str, list[ca.Function]]:
    """The C driver of the structured pass for a :class:`~identification.filtering.iekf_pass.FilterStep`,
    and the generated functions it calls.

    The driver has the signature of the generated-step pass
    (``vehid_iekf_pass(n_samples, n_u, n_y, n_state, u, y, q, r, c, dt, state, innovations)``)
    and updates ``state = [z; upper(P)]`` in place.
    """
    fs = filter_step
    measure, predict, tables = model_functions(fs)
    header = (
        "#include <math.h>\n"
        f"#define N_Z {fs.n_z}LL\n#define N_X {fs.n_states}LL\n#define N_Y {fs.n_y}LL\n"
        f"#define NNZ_H {len(tables['h_columns'])}\n#define NNZ_E {len(tables['e_columns'])}\n"
        f"#define PAPER_FORM {1 if fs.covariance == 'paper' else 0}\n"
        + _table("H_POINTERS", tables["h_pointers"]) + _table("H_COLUMNS", tables["h_columns"])
        + _table("E_POINTERS", tables["e_pointers"]) + _table("E_COLUMNS", tables["e_columns"])
    )
    return header + _LOOPS, [measure, predict]
