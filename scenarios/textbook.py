"""The seed appendix's worked examples, computed by the classical estimators.

Source: the textbook appendix "System identification, state and parameter
estimation techniques" (sections A.2-A.5), whose equations and tables are
images in our copy; every number here is recomputed from the stated data.

* ``kalman_example``: the scalar Kalman filter of A.3 (eq. A.92, phi = 1,
  P0 = 100, Q = 25, R = 15): P(k|k-1), K(k), P(k|k) for the first steps.
  Expected: 125, 0.8929, 13.39 at k = 1, settling at P(k|k) = 10.549.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from identification.kalman import kalman_filter

__all__ = ["kalman_example"]


def kalman_example(*, steps: int = 5, phi: float = 1.0, P0: float = 100.0, Q: float = 25.0, R: float = 15.0
                   ) -> list[dict[str, Any]]:
    """P(k|k-1), K(k), P(k|k) of the appendix's scalar example (A.92) for k = 1..steps.

    The covariances do not depend on the measurements, so the filter runs on zeros.
    """
    run = kalman_filter(np.zeros((steps, 1)), A=[[phi]], C=[[1.0]], Q=[[Q]], R=[[R]], x0=[0.0], P0=[[P0]])
    return [
        {"k": k + 1, "P_prior": float(run.P_prior[k, 0, 0]), "K": float(run.gain[k, 0, 0]),
         "P_post": float(run.P_post[k, 0, 0])}
        for k in range(steps)
    ]
