"""The data container and the fit metrics against hand-computed values."""

import numpy as np
import pytest

from vehid.identification import IOData, InputError, fit_metrics, nrmse_fit, percentage_explanation, r_squared
from vehid.identification import read_hdf5, read_record


def _record(n=100, dt=0.01):
    t = np.arange(n) * dt
    return IOData(t=t, u=np.sin(t)[:, None], y=np.column_stack([np.cos(t), t]), output_names=("a", "b"))


def test_container_is_immutable_and_validated():
    data = _record()
    assert data.n_samples == 100 and data.n_u == 1 and data.n_y == 2
    assert data.dt == pytest.approx(0.01, rel=1e-12)
    with pytest.raises(ValueError):
        data.y[0, 0] = 1.0  # read-only array
    with pytest.raises(InputError, match="non-finite"):
        IOData(t=data.t, u=np.full(100, np.nan), y=data.y)
    with pytest.raises(InputError, match="lengths must match"):
        IOData(t=data.t, u=data.u[:50], y=data.y)
    with pytest.raises(InputError, match="uniformly"):
        IOData(t=np.r_[0, 1, 3.0], u=[1, 2, 3], y=[1, 2, 3])


def test_slicing_and_selection():
    data = _record()
    first, second = data.split(0.3)
    assert first.n_samples == 30 and second.n_samples == 70
    only_b = data.select_outputs(["b"])
    np.testing.assert_array_equal(only_b.y[:, 0], data.t)
    with pytest.raises(InputError, match="unknown output 'c'"):
        data.select_outputs(["c"])


def test_percentage_explanation_closed_form():
    # eq. 17: R = (1 - sum e^2 / sum y^2) * 100; y = [1, -1], e = [0, 0.1] -> 1 - 0.01/2
    assert percentage_explanation([1.0, -1.0], [1.0, -0.9])[0] == pytest.approx(99.5, abs=1e-12)


def test_nrmse_and_r_squared_closed_form():
    y = np.array([0.0, 1.0, 2.0, 3.0])
    y_hat = y + np.array([0.1, -0.1, 0.1, -0.1])
    spread = np.sqrt(np.sum((y - 1.5) ** 2))  # sqrt(5)
    assert nrmse_fit(y, y_hat)[0] == pytest.approx(100 * (1 - 0.2 / spread), abs=1e-12)
    assert r_squared(y, y_hat)[0] == pytest.approx(1 - 0.04 / 5.0, abs=1e-12)
    metrics = fit_metrics(np.column_stack([y, y]), np.column_stack([y, y_hat]))
    assert metrics.percentage_explanation[0] == pytest.approx(100.0)
    assert metrics.mean_r_squared == pytest.approx((1 + 1 - 0.04 / 5.0) / 2)


def test_csv_round_trip(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text("t,steer,ay\n0,0.1,1\n0.5,0.2,2\n1.0,0.3,3\n")
    data = read_record(path, inputs=("steer",), outputs=("ay",))
    assert data.dt == pytest.approx(0.5)
    np.testing.assert_array_equal(data.y[:, 0], [1, 2, 3])
    with pytest.raises(InputError, match="unknown column 'yaw'"):
        read_record(path, inputs=("steer",), outputs=("yaw",))
    # dt beside a time column would silently override it: an error unless the time column is disabled
    with pytest.raises(InputError, match="has a time column 't': 'dt' would override it"):
        read_record(path, inputs=("steer",), outputs=("ay",), dt=0.1)
    by_dt = read_record(path, inputs=("steer",), outputs=("ay",), dt=0.1, time_column="none")
    assert by_dt.dt == pytest.approx(0.1)


def test_hdf5_round_trip(tmp_path):
    import h5py

    data = _record().replace(meta={"seed": 3})
    path = tmp_path / "rec.h5"
    with h5py.File(path, "w") as handle:
        data.to_hdf5(handle.create_group("data"))
    back = read_hdf5(path)
    np.testing.assert_array_equal(back.y, data.y)
    assert back.output_names == ("a", "b") and back.meta["seed"] == 3
