"""The navigator's time update of a segment (nav/propagation.py): its compiled loop
(_kernels.mech_segment) against the two modules it stands for, SensorErrors.compensate and
strapdown.run."""
import numpy as np

from ins_gnss_ros.nav import _kernels
from ins_gnss_ros.nav.earth import WGS84
from ins_gnss_ros.nav.increments import SensorErrors
from ins_gnss_ros.nav.strapdown import NavState, run


def test_the_compiled_segment_equals_compensation_then_mechanisation():
    rng = np.random.default_rng(7)
    start = NavState(0.9, 0.5, 120.0, np.array([12.0, -3.0, 0.4]),
                     np.array([0.9, 0.1, -0.2, 0.37]) / np.linalg.norm([0.9, 0.1, -0.2, 0.37]),
                     0.0)
    n = 20
    dts = 0.005 + 1e-4 * rng.standard_normal(n)
    th = rng.normal(0.0, 2e-3, (n, 3))
    dv = rng.normal(0.0, 5e-2, (n, 3)) + np.array([0.0, 0.0, 9.8]) * dts[:, None]
    cth, cdv = rng.normal(0.0, 1e-7, (n, 3)), rng.normal(0.0, 1e-6, (n, 3))
    errors = SensorErrors(gyro_bias=np.array([1e-3, -2e-3, 5e-4]),
                          accel_bias=np.array([0.05, -0.02, 0.1]),
                          gyro_scale=np.array([1e-3, -5e-4, 2e-3]),
                          accel_scale=np.array([-1e-3, 2e-3, 5e-4]))
    dt = float(dts.sum()) / n

    c_th, c_dv = errors.compensate(th, dv, dts)
    ref = run(start, c_th + cth, c_dv + cdv, dt)

    v, q, sums = start.v_enu.copy(), start.q_nb.copy(), np.empty((2, 3))
    lat, lon, h = _kernels.mech_segment(start.lat, start.lon, start.h, v, q, th, dv, cth, cdv,
                                        dts, errors.gyro_bias, errors.gyro_scale,
                                        errors.accel_bias, errors.accel_scale, dt,
                                        WGS84.kernel_params, sums)
    np.testing.assert_allclose([lat, lon], [ref["lat"][-1], ref["lon"][-1]], rtol=0, atol=1e-14)
    np.testing.assert_allclose(h, ref["h"][-1], rtol=0, atol=1e-9)
    np.testing.assert_allclose(v, ref["v_enu"][-1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(q, ref["q_nb"][-1], rtol=0, atol=1e-14)
    np.testing.assert_allclose(sums, [c_th.sum(axis=0), c_dv.sum(axis=0)], rtol=0, atol=1e-15)
