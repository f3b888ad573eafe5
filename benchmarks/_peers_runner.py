"""Score the peer libraries on the public records; runs inside the peers' own virtual environment.

    benchmarks/.peers-venv/bin/python benchmarks/_peers_runner.py SET [SET ...]

prints one JSON object: ``{"settings": ..., "versions": ..., "sets": {set:
{method: {"validation_fit_percent": [...], "seconds": s} or {"error": text}}}}``. The peers (SIPPY, nfoursid,
python-control, sysidentpy) are never imported by the workbench; this script
needs only them, NumPy, SciPy and ``_real_records.py`` beside it.

Each peer sees the estimation record with its mean removed (the peers do not
remove offsets themselves); the validation record is centred as ``vehid
identify`` centres it (``_real_records.validation_offsets``: the estimation
means for a held-out tail, its own means for a separate validation record). Linear models
have the workbench's default order (``ORDER``); each is simulated on the
validation input from its least-squares initial state (``_real_records``).
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
import time
import warnings

import numpy as np

import _real_records as records

ORDER = 4  # the workbench's default model order, for every linear model
NFOURSID_BLOCK_ROWS = 10  # block rows of the Hankel matrices: past/future horizon well above the order
MARKOV_PARAMETERS = 60  # python-control: impulse-response length estimated before the ERA realisation
NARX_LAGS = 4  # sysidentpy: output and input lags (an ARX of the same order as the state-space models)


def _sippy(method: str):
    def identify(u, y):
        from sippy_unipi import system_identification

        model = system_identification(y, u, method, SS_fixed_order=ORDER, SS_D_required=True)
        return model.A, model.B, model.C, model.D
    return identify


def _nfoursid(u, y):
    import pandas as pd
    from nfoursid.nfoursid import NFourSID

    frame = pd.DataFrame(np.column_stack([u, y]), columns=[f"u{i}" for i in range(u.shape[1])]
                         + [f"y{i}" for i in range(y.shape[1])])
    identifier = NFourSID(frame, output_columns=[f"y{i}" for i in range(y.shape[1])],
                          input_columns=[f"u{i}" for i in range(u.shape[1])], num_block_rows=NFOURSID_BLOCK_ROWS)
    identifier.subspace_identification()
    model, _ = identifier.system_identification(rank=ORDER)
    return model.a, model.b, model.c, model.d


def _control_era(u, y):
    import control

    markov = control.markov(y.T, u.T, m=MARKOV_PARAMETERS)
    markov = np.asarray(markov).reshape(y.shape[1], u.shape[1], MARKOV_PARAMETERS)
    rows = (MARKOV_PARAMETERS - 1) // 2
    model, _ = control.eigensys_realization(markov, ORDER, m=rows, n=rows)
    return model.A, model.B, model.C, model.D


LINEAR_PEERS = {
    "sippy-n4sid": _sippy("N4SID"),
    "sippy-moesp": _sippy("MOESP"),
    "sippy-cva": _sippy("CVA"),
    "nfoursid": _nfoursid,
    "control-okid-era": _control_era,
}


def _sysidentpy(degree: int):
    """Polynomial (N)ARX by FROLS, one model per output (sysidentpy is multi-input single-output)."""

    def score(u_est, y_est, u_val, y_val):
        from sysidentpy.basis_function import Polynomial
        from sysidentpy.model_structure_selection import FROLS
        from sysidentpy.parameter_estimation import LeastSquares

        fits = []
        for j in range(y_est.shape[1]):
            lags = [list(range(1, NARX_LAGS + 1))] * u_est.shape[1] if u_est.shape[1] > 1 else NARX_LAGS
            model = FROLS(ylag=NARX_LAGS, xlag=lags, basis_function=Polynomial(degree=degree),
                          estimator=LeastSquares(), order_selection=True, info_criteria="aic", model_type="NARMAX")
            model.fit(X=u_est, y=y_est[:, [j]])
            y_hat = model.predict(X=u_val, y=y_val[:, [j]])  # free run from the first NARX_LAGS measured outputs
            fits.append(records.nrmse_fit(y_val[:, [j]], np.asarray(y_hat).reshape(-1, 1))[0])
        return fits
    return score


NARX_PEERS = {"sysidentpy-arx": _sysidentpy(1), "sysidentpy-narx2": _sysidentpy(2)}


def run(name: str) -> dict:
    entry = records.record_set(name)
    (u_est, y_est), (u_val, y_val) = records.load(entry)
    u_offset, y_offset = u_est.mean(axis=0), y_est.mean(axis=0)
    u_c, y_c = u_est - u_offset, y_est - y_offset
    # the validation samples are centred as `vehid identify` centres them (the estimation means, or a separate
    # validation record's own), so every method is scored on the same numbers
    u_val_offset, y_val_offset = records.validation_offsets(entry, (u_est, y_est), (u_val, y_val))
    results = {}
    for method, identify in {**LINEAR_PEERS, **NARX_PEERS}.items():
        start = time.perf_counter()
        try:
            with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
                warnings.simplefilter("ignore")
                if method in NARX_PEERS:
                    fits = identify(u_c, y_c, u_val - u_val_offset, y_val - y_val_offset)
                else:
                    A, B, C, D = identify(u_c, y_c)
                    fits = records.score_discrete(A, B, C, D, u_val, y_val, u_val_offset, y_val_offset)
            results[method] = {"validation_fit_percent": fits, "seconds": time.perf_counter() - start}
        except Exception as exc:  # a peer failing on a record is a result, not a crash of the benchmark
            results[method] = {"error": f"{type(exc).__name__}: {exc}"[:300], "seconds": time.perf_counter() - start}
    return results


SETTINGS = {
    "order": ORDER,
    "sippy": "N4SID, MOESP, CVA with SS_fixed_order = order, D estimated, other options SIPPY's defaults",
    "nfoursid": f"num_block_rows = {NFOURSID_BLOCK_ROWS}, rank = order",
    "control": f"markov (first {MARKOV_PARAMETERS} Markov parameters by least squares) then eigensys_realization",
    "sysidentpy": f"FROLS, polynomial degree 1 (ARX) and 2 (NARX), {NARX_LAGS} output and input lags, AIC, "
                  "least squares, one model per output; free-run simulation",
}


def versions() -> dict:
    from importlib.metadata import PackageNotFoundError, version

    found = {}
    for package in ("sippy-unipi", "nfoursid", "control", "sysidentpy", "numpy", "scipy"):
        try:
            found[package] = version(package)
        except PackageNotFoundError:
            found[package] = None
    return found


if __name__ == "__main__":
    json.dump({"settings": SETTINGS, "versions": versions(), "sets": {name: run(name) for name in sys.argv[1:]}},
              sys.stdout)
    sys.stdout.write("\n")
