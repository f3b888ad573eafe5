"""Score the peer libraries on the public records; runs inside the peers' own virtual environment.

    benchmarks/.peers-venv/bin/python benchmarks/_peers_runner.py [--orders 2-8] [--fractions 0.3,0.35]
        [--rule holdout|estimation-split] [--tolerance 0.5] [--inner-holdout 0.3] SET [SET ...]

prints, after each split, one JSON line holding the results so far (the last line: all of them): ``{"settings": ..., "versions": ..., "sets": {set: {split: {method: {"order": n,
"validation_fit_percent": [...], "fit_by_order": {n: mean fit}, "models_by_order": {n: {"A": ..., "B": ..., "C": ...,
"D": ...}} (linear peers), "seconds": s} or {"error": text}}}}}``, where
``split`` is the held-out fraction as text (``"0.3"``) or ``"published"`` for a record published with its own
validation record. The peers (SIPPY, nfoursid, python-control, sysidentpy) are never imported by the
workbench; this script needs only them, NumPy, SciPy and ``_real_records.py`` beside it.

Each peer sees the estimation record with its mean removed (the peers do not
remove offsets themselves); the validation record is centred as ``vehid
identify`` centres it (``_real_records.validation_offsets``: the estimation
means for a held-out tail, its own means for a separate validation record).
Every model is simulated on the validation input from its least-squares
initial state (``_real_records``: MATLAB ``compare``'s rule). The linear
peers' discrete models are printed too, so that the benchmark can score them
as ``vehid identify`` scores its own (k-step prediction where a model is
unstable), which this environment cannot: it has no workbench.

Every peer gets the order search ``vehid identify --order 2-8`` gets: it is
identified at each order (state dimension; the ARX lag count for
sysidentpy), and the smallest order within ``--tolerance`` points of the best
mean fit is chosen (``_real_records.choose_order``). The fits that choose are,
by ``--rule``: ``holdout``, the held-out fits themselves, as ``identify
--validation F --order 2-8`` ranks its orders; ``estimation-split``, fits on
the last ``--inner-holdout`` of the estimation part by models identified on
the rest of it, the chosen order then identified again on the whole
estimation part and scored once on the held-out part.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import time
import warnings

import numpy as np

import _real_records as records

ORDERS = tuple(range(2, 9))  # as `identify --order 2-8`
NFOURSID_BLOCK_ROWS = 10  # block rows of the Hankel matrices: past/future horizon above every order searched
MARKOV_PARAMETERS = 60  # python-control: impulse-response length estimated before the ERA realisation


def _sippy(method: str):
    def identify(u, y, order):
        from sippy_unipi import system_identification

        model = system_identification(y, u, method, SS_fixed_order=order, SS_D_required=True)
        return model.A, model.B, model.C, model.D
    return identify


def _nfoursid(u, y, order):
    import pandas as pd
    from nfoursid.nfoursid import NFourSID

    frame = pd.DataFrame(np.column_stack([u, y]), columns=[f"u{i}" for i in range(u.shape[1])]
                         + [f"y{i}" for i in range(y.shape[1])])
    identifier = NFourSID(frame, output_columns=[f"y{i}" for i in range(y.shape[1])],
                          input_columns=[f"u{i}" for i in range(u.shape[1])], num_block_rows=NFOURSID_BLOCK_ROWS)
    identifier.subspace_identification()
    model, _ = identifier.system_identification(rank=order)
    return model.a, model.b, model.c, model.d


def _control_era(u, y, order):
    import control

    markov = control.markov(y.T, u.T, m=MARKOV_PARAMETERS)
    markov = np.asarray(markov).reshape(y.shape[1], u.shape[1], MARKOV_PARAMETERS)
    rows = (MARKOV_PARAMETERS - 1) // 2
    model, _ = control.eigensys_realization(markov, order, m=rows, n=rows)
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

    def score(u_est, y_est, u_val, y_val, lags_count):
        from sysidentpy.basis_function import Polynomial
        from sysidentpy.model_structure_selection import FROLS
        from sysidentpy.parameter_estimation import LeastSquares

        fits = []
        for j in range(y_est.shape[1]):
            lags = [list(range(1, lags_count + 1))] * u_est.shape[1] if u_est.shape[1] > 1 else lags_count
            model = FROLS(ylag=lags_count, xlag=lags, basis_function=Polynomial(degree=degree),
                          estimator=LeastSquares(), order_selection=True, info_criteria="aic", model_type="NARMAX")
            model.fit(X=u_est, y=y_est[:, [j]])
            y_hat = model.predict(X=u_val, y=y_val[:, [j]])  # free run from the first measured outputs
            fits.append(records.nrmse_fit(y_val[:, [j]], np.asarray(y_hat).reshape(-1, 1))[0])
        return fits
    return score


NARX_PEERS = {"sysidentpy-arx": _sysidentpy(1), "sysidentpy-narx2": _sysidentpy(2)}


def _fits(method: str, estimation, validation, order: int) -> tuple[list[float | None], dict | None]:
    """Hold-out fit per output of ``method`` at ``order``: identified on ``estimation``, scored on ``validation``.

    Both parts are raw; the estimation means are removed before identifying,
    and ``validation`` arrives with its offsets as a pair ``((u, y), (u0, y0))``.
    Also returns a linear peer's discrete model (``A``, ``B``, ``C``, ``D`` as
    lists), for the benchmark to score as ``identify`` scores; None for NARX.
    """
    (u_est, y_est), ((u_val, y_val), (u_val_offset, y_val_offset)) = estimation, validation
    u_c, y_c = u_est - u_est.mean(axis=0), y_est - y_est.mean(axis=0)
    with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
        warnings.simplefilter("ignore")
        if method in NARX_PEERS:
            return NARX_PEERS[method](u_c, y_c, u_val - u_val_offset, y_val - y_val_offset, order), None
        A, B, C, D = LINEAR_PEERS[method](u_c, y_c, order)
        model = {key: np.atleast_2d(np.asarray(matrix, dtype=float)).tolist() for key, matrix in zip("ABCD", (A, B, C, D))}
        return records.score_discrete(A, B, C, D, u_val, y_val, u_val_offset, y_val_offset), model


def _mean(fits: list[float | None] | None) -> float | None:
    return None if not fits or any(f is None for f in fits) else float(np.mean(fits))


def _fits_by_order(method: str, estimation, validation, orders
                   ) -> tuple[dict[int, list | None], dict[int, str], dict[int, dict]]:
    """Hold-out fit per output at each order, and each linear model; a peer failing at an order is recorded, not raised."""
    fits, errors, models = {}, {}, {}
    for order in orders:
        try:
            fits[order], model = _fits(method, estimation, validation, order)
        except Exception as exc:  # a peer failing at one order is a result, not a crash of the benchmark
            fits[order], errors[order], model = None, f"{type(exc).__name__}: {exc}"[:200], None
        if model is not None:
            models[order] = model
    return fits, errors, models


def search(method: str, estimation, validation, options) -> dict:
    """One peer's order search and the hold-out fit of the order it chooses."""
    held, errors, models = _fits_by_order(method, estimation, validation, options.orders)
    row: dict = {"fit_by_order": {order: _mean(fits) for order, fits in held.items()}}
    if models:
        row["models_by_order"] = models
    if options.rule == "holdout":
        ranking = row["fit_by_order"]
    else:
        # the estimation part split again, as identify holds out a part to choose an order without validation data
        u_est, y_est = estimation
        cut = records.split_index(len(u_est), options.inner_holdout)
        inner_estimation, inner_validation = (u_est[:cut], y_est[:cut]), (u_est[cut:], y_est[cut:])
        inner_offsets = (inner_estimation[0].mean(axis=0), inner_estimation[1].mean(axis=0))
        inner, _, _ = _fits_by_order(method, inner_estimation, (inner_validation, inner_offsets), options.orders)
        ranking = {order: _mean(fits) for order, fits in inner.items()}
        row["selection_fit_by_order"] = ranking
    order = records.choose_order(ranking, options.tolerance)
    if order is None:
        row["error"] = "no order gave a finite fit: " + "; ".join(f"n = {n}: {e}" for n, e in errors.items())
        return row
    row.update(order=order, validation_fit_percent=held[order])
    if errors:
        row["errors_by_order"] = errors
    return row


def splits(entry, fractions) -> list[tuple[str, float]]:
    """The held-out fractions of a record by name; a record published with its validation record has one split."""
    if entry.validation_path_columns is not None:
        return [("published", records.HOLDOUT)]
    return [(f"{fraction:g}", fraction) for fraction in fractions]


def run(name: str, options, done=lambda results: None) -> dict:
    """Every peer's order search on each split of the record; ``done(results)`` after each split."""
    entry = records.record_set(name)
    results: dict = {}
    for label, fraction in splits(entry, options.fractions):
        estimation, validation = records.load(entry, fraction)
        # the validation samples are centred as `vehid identify` centres them (the estimation means, or a separate
        # validation record's own), so every method is scored on the same numbers
        offsets = records.validation_offsets(entry, estimation, validation)
        rows = {}
        for method in (*LINEAR_PEERS, *NARX_PEERS):
            start = time.perf_counter()
            rows[method] = {**search(method, estimation, (validation, offsets), options),
                            "seconds": time.perf_counter() - start}
        results[label] = rows
        done(results)
    return results


def settings(options) -> dict:
    return {
        "orders": list(options.orders),
        "order_rule": options.rule,
        "order_tolerance": options.tolerance,
        **({"inner_holdout": options.inner_holdout} if options.rule == "estimation-split" else {}),
        "sippy": "N4SID, MOESP, CVA with SS_fixed_order = order, D estimated, other options SIPPY's defaults",
        "nfoursid": f"num_block_rows = {NFOURSID_BLOCK_ROWS}, rank = order",
        "control": f"markov (first {MARKOV_PARAMETERS} Markov parameters by least squares) then "
                   "eigensys_realization of the order",
        "sysidentpy": "FROLS, polynomial degree 1 (ARX) and 2 (NARX), order = output and input lags, AIC, "
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


def _orders(text: str) -> tuple[int, ...]:
    low, _, high = text.partition("-")
    return tuple(range(int(low), int(high or low) + 1))


def parse(argv: list[str] | None = None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sets", nargs="+")
    parser.add_argument("--orders", type=_orders, default=ORDERS, help="orders searched, e.g. 2-8")
    parser.add_argument("--fractions", type=lambda text: [float(f) for f in text.split(",")],
                        default=[records.HOLDOUT], help="held-out fractions, e.g. 0.3,0.35")
    parser.add_argument("--rule", choices=("holdout", "estimation-split"), default="holdout")
    parser.add_argument("--tolerance", type=float, default=records.ORDER_TOLERANCE)
    parser.add_argument("--inner-holdout", type=float, default=records.HOLDOUT)
    return parser.parse_args(argv)


def main() -> None:
    """Print the results so far as one JSON line after each split: the last line is the whole run, and a run
    stopped early leaves what it finished."""
    options = parse()
    output = {"settings": settings(options), "versions": versions(), "sets": {}}

    def show(results: dict, name: str) -> None:
        output["sets"][name] = results
        sys.stdout.write(json.dumps(output) + "\n")
        sys.stdout.flush()

    for name in options.sets:
        run(name, options, lambda results, name=name: show(results, name))


if __name__ == "__main__":
    main()
