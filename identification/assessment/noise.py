"""How much white noise each output of a record carries, estimated from the record alone.

The IEKF weighs its outputs by it (``measurement_noise="data"``), output error and the grey-box
filter subtract it from each output's power to weigh the noise-free part.
"""

from __future__ import annotations

import math

import numpy as np

from ..data import IOData, as_records

__all__ = ["output_noise_variance"]


def output_noise_variance(records: IOData | tuple[IOData, ...]) -> np.ndarray:
    """The variance of each output's white noise, estimated from the records' k-th differences, k = 1, 2, 3.

    Of white noise of variance s^2 the k-th difference has the mean square
    ``binom(2k, k) s^2``; a smooth signal adds little to it where the record
    is sampled fast against its dynamics, and never subtracts. Each k gives
    an upper bound, pooled over the records; the smallest is returned (in
    the outputs' units squared). Its relative standard error on N samples of
    pure white noise is below ``sqrt(4.7 / N)`` (about 5 % at N = 2000).
    """
    records = as_records(records)
    bounds = []
    for k in (1, 2, 3):
        squares = sum(np.sum(np.diff(record.y, k, axis=0) ** 2, axis=0) for record in records)
        count = sum(max(record.n_samples - k, 0) for record in records)
        bounds.append(squares / max(count, 1) / math.comb(2 * k, k))
    return np.min(bounds, axis=0)
