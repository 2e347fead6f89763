"""imu_preprocessor node: calibration recovered from simulated raw data, coning/sculling increments
against the core, every kind of bad sample handled without a crash, parameters validated."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from rclpy.parameter import Parameter

from ins_gnss_ros.imu.calibration import ImuCalibration
from ins_gnss_ros.nav.coning import to_navigation_rate
from ins_gnss_ros.nav.rotations import dcm_from_euler
from ins_gnss_ros.nav.sensor_errors import ImuGrade, TriadErrors
from ins_gnss_ros.sim.imu_sim import ImuSpec, simulate_imu
from ins_gnss_ros.sim.trajectory import CarMotion, Route, generate

DEG = np.pi / 180
NS = 1_000_000_000
T0_NS = 1_780_000_000 * NS  # a 2026 POSIX stamp: float seconds would resolve only ~0.2 µs
G_UP = np.array([0.0, 0.0, 9.81])

# A deliberately bad sensor: biases, scale factors and non-orthogonality with temperature drift,
# g-sensitivity, mounted upside down and turned 90 deg in yaw (sensor -> base_link).
CAL = ImuCalibration.from_dict({
    "gyro": {"bias": [[0.02, -0.01, 0.015], [1e-4, -2e-4, 5e-5]], "scale": [0.01, -0.02, 0.005],
             "nonorthogonality": [[0, 1e-3, -2e-3], [5e-4, 0, 1e-3], [-1e-3, 2e-3, 0]]},
    "accel": {"bias": [[0.3, -0.2, 0.1], [2e-3, 1e-3, -1e-3]], "scale": [[0.02, 0.01, -0.01]],
              "nonorthogonality": [[0, 2e-3, 0], [0, 0, -1e-3], [1e-3, 0, 0]]},
    "gyro_g_sensitivity": (1e-4 * np.arange(9).reshape(3, 3)).tolist(),
    "mounting_rpy": [np.pi, 0.0, np.pi / 2],
    "temperature_ref": 25.0,
})
TEMPERATURE = 40.0


def _params(**over) -> list[Parameter]:
    """The CAL calibration as node parameters, plus overrides."""
    d = CAL.to_dict()
    values = {"calibration.temperature_ref": d["temperature_ref"],
              "calibration.gyro_g_sensitivity": np.ravel(d["gyro_g_sensitivity"]).tolist(),
              "mounting_rpy_deg": np.degrees(d["mounting_rpy"]).tolist()}
    for triad in ("gyro", "accel"):
        for k in ("bias", "scale", "nonorthogonality"):
            values[f"calibration.{triad}.{k}"] = np.ravel(d[triad][k]).tolist()
    values.update(over)
    return [Parameter(k, value=v) for k, v in values.items()]


def _imu_msg(t_ns: int, gyro, accel, frame_id="base_link"):
    """A raw sample; in base_link's axes unless ``frame_id`` names another frame (whose
    mounting the node takes from the parameters or /tf_static)."""
    from sensor_msgs.msg import Imu

    from ins_gnss_ros.nodes.convert import to_vector3
    from ins_gnss_ros.io import ns_to_stamp

    msg = Imu(angular_velocity=to_vector3(gyro), linear_acceleration=to_vector3(accel))
    msg.header.stamp = ns_to_stamp(t_ns)
    msg.header.frame_id = frame_id
    return msg


class _Graph:
    """The node on an InProcessBus with every output recorded."""

    def __init__(self, ros_context, params):
        from ins_gnss_ros.nodes.base import InProcessBus
        from ins_gnss_ros.nodes.imu_preprocessor_node import ImuPreprocessorNode

        self.bus = InProcessBus()
        self.out = {"/imu/data": [], "/imu/delta": [], "/imu/mag": []}
        self.bus.recorders.append(
            lambda topic, msg: self.out[topic].append(msg) if topic in self.out else None)
        self.node = ImuPreprocessorNode(context=ros_context, bus=self.bus,
                                        parameter_overrides=params)

    def send(self, topic, msg):
        self.bus.publish(topic, msg)
        self.bus.drain()

    def imu(self, t_ns, gyro, accel, frame_id="base_link"):
        self.send("imu/data_raw", _imu_msg(t_ns, gyro, accel, frame_id))

    def close(self):
        self.node.destroy_node()


@pytest.fixture
def graph(ros_context):
    """Nodes on a bus. Most streams here repeat one exact reading, which the frozen-sensor check
    would reject: it is off unless a test sets max_identical_samples."""
    graphs = []

    def make(*params):
        # The tests' streams are 200 Hz unless they say otherwise.
        for name, value in (("max_identical_samples", 0), ("rate_hz", 200.0)):
            if not any(p.name == name for p in params):
                params = (Parameter(name, value=value), *params)
        g = _Graph(ros_context, list(params))
        graphs.append(g)
        return g
    yield make
    for g in graphs:
        g.close()


def _white_noise_imu(rate, duration, gyro_sigma, accel_sigma, seed=7):
    """A car pulling away into a banked left turn, measured by an IMU with white noise only."""
    route = Route(yaw0=0.3).hold(1.0).change_speed(10.0, 2.5).set_bank(0.05, 2.0)
    route.turn(np.pi / 2, radius=25.0).hold(30.0)
    traj = generate(CarMotion(route), 60 * DEG, 30 * DEG, 20.0, duration, rate, oversample=2)
    grade = ImuGrade("white", TriadErrors(gyro_sigma / np.sqrt(rate), 0.0),
                     TriadErrors(accel_sigma / np.sqrt(rate), 0.0))
    return traj, simulate_imu(traj, ImuSpec(grade, rate=rate), seed)


def _stamps_ns(meas):
    return T0_NS + np.round(meas.t * NS).astype(np.int64)


def test_recovers_rates_and_forces_within_noise(graph):
    """Raw = calibration model applied to a simulated IMU; the node must undo it exactly and leave
    only the simulated white noise around the true rates and forces."""
    from sensor_msgs.msg import Temperature

    rate, sg, sa = 200.0, 0.2 * DEG, 0.02
    traj, meas = _white_noise_imu(rate, 12.0, sg, sa)
    gyro_raw, accel_raw = CAL.simulate_raw(meas.gyro, meas.accel, TEMPERATURE)
    g = graph(*_params(use_temperature=True))
    g.send("imu/temperature", Temperature(temperature=TEMPERATURE))
    stamps = _stamps_ns(meas)
    for k in range(len(stamps)):
        g.imu(int(stamps[k]), gyro_raw[k], accel_raw[k])
    data = g.out["/imu/data"]
    assert len(data) == len(stamps) and sum(g.node.diag.counts.values()) == 0
    assert {m.header.frame_id for m in data} == {"base_link"}
    w = np.array([[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z] for m in data])
    f = np.array([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z]
                  for m in data])
    np.testing.assert_allclose(w, meas.gyro, rtol=0, atol=1e-12)
    np.testing.assert_allclose(f, meas.accel, rtol=0, atol=1e-11)
    # Against the truth (interval means of the trajectory): zero mean, the simulated sigma.
    err_w, err_f = w - traj.dtheta / meas.dt, f - traj.dv / meas.dt
    n = len(err_w)
    assert np.all(np.abs(err_w.mean(0)) < 4 * sg / np.sqrt(n))
    assert np.all(np.abs(err_f.mean(0)) < 4 * sa / np.sqrt(n))
    print(f"\nraw 200 Hz IMU through the node: |recovered - simulated sensor| max "
          f"{abs(w - meas.gyro).max():.1e} rad/s, {abs(f - meas.accel).max():.1e} m/s^2; error "
          f"against truth: mean {np.degrees(err_w.mean(0)) * 3600} deg/h, "
          f"{err_f.mean(0) * 1e3} mm/s^2, std {np.degrees(err_w.std(0))} deg/s (simulated "
          f"{np.degrees(sg):.3f}), {err_f.std(0)} m/s^2 (simulated {sa})")
    np.testing.assert_allclose(err_w.std(0), sg, rtol=0.05)
    np.testing.assert_allclose(err_f.std(0), sa, rtol=0.05)
    # Without the compensation the same raw data would be off by far more than the noise.
    assert np.sqrt(np.mean((gyro_raw - traj.dtheta / meas.dt) ** 2)) > 10 * sg


@pytest.mark.parametrize("method", ["two_sample", "one_sample"])
def test_delta_equals_core_coning_sculling_at_1200_hz(graph, method):
    rate, n_sub = 1200.0, 12
    traj, meas = _white_noise_imu(rate, 4.0, 0.1 * DEG, 0.01)
    gyro_raw, accel_raw = CAL.simulate_raw(meas.gyro, meas.accel)
    g = graph(*_params(rate_hz=rate, nav_rate_hz=100.0, coning_method=method))
    stamps = _stamps_ns(meas)
    for k in range(len(stamps)):
        g.imu(int(stamps[k]), gyro_raw[k], accel_raw[k])
    deltas = g.out["/imu/delta"]
    m = len(stamps) // n_sub
    assert len(deltas) == m
    # The core on the same samples: rate x interval, the interval from the (integer ns) stamps.
    dt = np.diff(stamps) / NS
    dt = np.concatenate([[1.0 / rate], dt])  # the first sample: the nominal interval
    phi, dv = to_navigation_rate(meas.gyro * dt[:, None], meas.accel * dt[:, None], n_sub, method)
    got_phi = np.array([[d.delta_angle.x, d.delta_angle.y, d.delta_angle.z] for d in deltas])
    got_dv = np.array([[d.delta_velocity.x, d.delta_velocity.y, d.delta_velocity.z]
                       for d in deltas])
    print(f"\n{method}, 1200 Hz -> 100 Hz: node - core max |d phi| {abs(got_phi - phi).max():.1e}"
          f" rad, |d dv| {abs(got_dv - dv).max():.1e} m/s over {m} increments")
    np.testing.assert_allclose(got_phi, phi, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got_dv, dv, rtol=0, atol=1e-12)
    ends = stamps[n_sub - 1::n_sub][:m]
    assert [d.header.stamp.sec * NS + d.header.stamp.nanosec for d in deltas] == ends.tolist()
    np.testing.assert_allclose([d.dt for d in deltas],
                               np.add.reduceat(dt, np.arange(0, m * n_sub, n_sub)), rtol=1e-12)
    # And the increments are the motion's: the attitude change over each interval.
    true_dtheta = traj.dtheta[:m * n_sub].reshape(m, n_sub, 3).sum(1)
    # (white rate noise 0.1 deg/s per sample: sqrt(n_sub) / rate of it per increment)
    noise = 0.1 * DEG * np.sqrt(n_sub) / rate
    assert np.sqrt(np.mean((got_phi - true_dtheta) ** 2)) < 1.2 * noise


# -- bad samples: one case each; the node stays up, says why, passes nothing non-finite on ------
DT_NS = NS // 200
GOOD_W = np.array([0.01, -0.02, 0.03])


def _run_stream(g, n, bad_at=None, bad=None):
    """n samples at 200 Hz; at index ``bad_at`` call ``bad(g, t_ns)`` instead of a good sample."""
    for k in range(n):
        t = T0_NS + (k + 1) * DT_NS
        if k == bad_at:
            bad(g, t)
        else:
            g.imu(t, GOOD_W, G_UP)


def _finite_outputs(g):
    for m in g.out["/imu/data"]:
        assert np.isfinite([m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z,
                            m.linear_acceleration.x, m.linear_acceleration.y,
                            m.linear_acceleration.z]).all()
    for d in g.out["/imu/delta"]:
        assert np.isfinite([d.delta_angle.x, d.delta_angle.y, d.delta_angle.z, d.delta_velocity.x,
                            d.delta_velocity.y, d.delta_velocity.z, d.dt]).all()


BAD_SAMPLES = {
    "nan": (lambda g, t: g.imu(t, [np.nan, 0, 0], G_UP), "imu sample rejected: non_finite"),
    "inf": (lambda g, t: g.imu(t, GOOD_W, [0, np.inf, 9.8]), "imu sample rejected: non_finite"),
    "gyro saturated": (lambda g, t: g.imu(t, [0, 0, 40.0], G_UP), "imu sample rejected: saturated"),
    "accel saturated": (lambda g, t: g.imu(t, GOOD_W, [0, 0, 160.0]),
                        "imu sample rejected: saturated"),
    "duplicate stamp": (lambda g, t: (g.imu(t - DT_NS, GOOD_W, G_UP), g.imu(t, GOOD_W, G_UP)),
                        "imu sample rejected: duplicate_stamp"),
    "backwards stamp": (lambda g, t: (g.imu(t - 3 * DT_NS, GOOD_W, G_UP), g.imu(t, GOOD_W, G_UP)),
                        "imu sample rejected: backwards_stamp"),
}


@pytest.mark.parametrize("case", sorted(BAD_SAMPLES))
def test_bad_sample_is_counted_and_never_passed_on(graph, case):
    bad, reason = BAD_SAMPLES[case]
    g = graph()
    _run_stream(g, 40, bad_at=20, bad=bad)
    assert g.node.diag.counts[reason] == 1
    _finite_outputs(g)
    assert all(m.header.stamp.nanosec != 0 or m.header.stamp.sec != 0 for m in g.out["/imu/data"])
    deltas = g.out["/imu/delta"]
    # A lost sample is bridged: the increments keep their 100 Hz step and see the true rate.
    assert len(deltas) == 20
    np.testing.assert_allclose([d.dt for d in deltas], 0.01, rtol=1e-9)
    np.testing.assert_allclose([d.delta_angle.z for d in deltas], GOOD_W[2] * 0.01, rtol=1e-9)
    if case in ("nan", "inf") or "saturated" in case:
        assert g.node.diag.counts["imu gap bridged"] == 1
        assert len(g.out["/imu/data"]) == 39  # the bridged sample is not a measurement


def test_short_gap_is_bridged_long_gap_restarts(graph):
    g = graph(Parameter("max_bridge_samples", value=3))
    t = T0_NS
    for k in range(10):
        t += DT_NS
        g.imu(t, GOOD_W, G_UP)
    t += 3 * DT_NS                                  # 2 samples lost: bridged
    g.imu(t, GOOD_W, G_UP)
    assert g.node.diag.counts["imu gap bridged"] == 1 and g.node.preprocessor.synthesised == 2
    assert len(g.out["/imu/delta"]) == 6            # 12 samples of 2
    t += 50 * DT_NS                                 # 49 lost: reported, integration restarts
    for k in range(4):
        g.imu(t, GOOD_W, G_UP)
        t += DT_NS
    assert g.node.diag.counts["imu gap longer than max_bridge_samples: integration restarted"] == 1
    deltas = g.out["/imu/delta"]
    assert len(deltas) == 8
    np.testing.assert_allclose([d.dt for d in deltas], 0.01, rtol=1e-9)  # no 0.25 s increment
    _finite_outputs(g)


def test_frozen_sensor_is_rejected_then_a_gap(graph):
    """A stuck sensor keeps sending its last reading with new stamps (fault class freeze): from
    the 5th identical sample on they are rejected and counted, and the gap they leave restarts
    the integration when the readings change again."""
    g = graph(Parameter("max_identical_samples", value=5))
    rng = np.random.default_rng(3)
    t = T0_NS
    for k in range(60):
        t += DT_NS
        frozen = 20 <= k < 50
        noise = 1e-3 * rng.standard_normal(6) if not frozen else noise
        g.imu(t, GOOD_W + noise[:3], G_UP + noise[3:])
    # The sample before the freeze and its first 3 repeats pass; the other 27 repeats do not.
    assert g.node.diag.counts["imu sample rejected: frozen"] == 27
    assert g.node.diag.counts[
        "imu gap longer than max_bridge_samples: integration restarted"] == 1
    assert len(g.out["/imu/data"]) == 60 - 27
    _finite_outputs(g)


def test_magnetometer_rotated_and_bad_samples_dropped(graph):
    from sensor_msgs.msg import MagneticField

    from ins_gnss_ros.nodes.convert import to_vector3
    from ins_gnss_ros.io import ns_to_stamp

    g = graph(Parameter("mounting_rpy_deg", value=[180.0, 0.0, 90.0]))
    c_bs = dcm_from_euler(np.pi, 0.0, np.pi / 2)
    m_s = np.array([10e-6, -5e-6, 40e-6])

    def mag(t_ns, m, cov0=-1.0):
        msg = MagneticField(magnetic_field=to_vector3(m))
        msg.header.stamp = ns_to_stamp(t_ns)
        msg.magnetic_field_covariance[0] = cov0
        return msg
    g.send("imu/mag_raw", mag(T0_NS, m_s, cov0=1e-14))
    g.send("imu/mag_raw", mag(T0_NS + 10 * DT_NS, [np.nan, 0, 0]))
    g.send("imu/mag_raw", mag(T0_NS, m_s))         # duplicate stamp
    g.send("imu/mag_raw", mag(T0_NS + 20 * DT_NS, m_s))
    out = g.out["/imu/mag"]
    assert len(out) == 2
    # Rx(180) flips y and z, then Rz(90) turns x to y and y to -x: sensor (x, y, z) is
    # base_link (-y, x, -z) read the other way round.
    np.testing.assert_allclose([out[0].magnetic_field.x, out[0].magnetic_field.y,
                                out[0].magnetic_field.z], [-5e-6, 10e-6, -40e-6], atol=1e-18)
    np.testing.assert_allclose(np.reshape(out[0].magnetic_field_covariance, (3, 3)),
                               c_bs @ np.diag([1e-14, 0, 0]) @ c_bs.T, atol=1e-30)
    assert out[1].magnetic_field_covariance[0] == -1.0
    counts = g.node.diag.counts
    assert counts["magnetometer sample rejected: non_finite"] == 1
    assert counts["magnetometer sample rejected: stamp not after the previous one"] == 1


def test_imu_covariances_rotated_into_each_messages_own_arrays(graph):
    """The driver's covariances, rotated into base_link (memoised per distinct covariance), are
    copied into every output message: no two messages share an array."""
    g = graph(Parameter("mounting_rpy_deg", value=[180.0, 0.0, 90.0]))
    c_bs = dcm_from_euler(np.pi, 0.0, np.pi / 2)
    cov_w, cov_f = np.diag([1e-6, 2e-6, 3e-6]), np.diag([1e-4, 2e-4, 4e-4])
    for k in range(3):
        msg = _imu_msg(T0_NS + k * DT_NS, GOOD_W, G_UP)
        msg.angular_velocity_covariance[:] = cov_w.ravel()
        msg.linear_acceleration_covariance[:] = -1.0 if k == 2 else cov_f.ravel()  # unknown
        g.send("imu/data_raw", msg)
    out = g.out["/imu/data"]
    for m in out:
        np.testing.assert_allclose(np.reshape(m.angular_velocity_covariance, (3, 3)),
                                   c_bs @ cov_w @ c_bs.T, rtol=0, atol=1e-20)
        assert m.orientation_covariance[0] == -1.0
    np.testing.assert_allclose(np.reshape(out[0].linear_acceleration_covariance, (3, 3)),
                               c_bs @ cov_f @ c_bs.T, rtol=0, atol=1e-18)
    assert list(out[2].linear_acceleration_covariance) == [-1.0] * 9
    arrays = [a for m in out for a in (m.angular_velocity_covariance,
                                       m.linear_acceleration_covariance)]
    assert not any(np.shares_memory(a, b) for i, a in enumerate(arrays) for b in arrays[i + 1:])


@pytest.mark.parametrize("enabled", [False, True])
def test_filter_corrections_only_when_enabled(graph, enabled):
    from ins_gnss_msgs.msg import InsCorrection

    g = graph(Parameter("apply_filter_corrections", value=enabled))
    corr = InsCorrection(sequence=1)
    corr.gyro_bias.z = 0.01
    corr.accel_scale_factor.z = 0.01
    g.send("ins/correction", corr)
    bad = InsCorrection(sequence=2)
    bad.gyro_bias.x = np.nan
    g.send("ins/correction", bad)
    g.imu(T0_NS, GOOD_W, G_UP)
    out = g.out["/imu/data"][0]
    if enabled:
        # Residual model x_cal = (1 + s) x + b: the filter says 0.01 rad/s and 1 % too much.
        assert out.angular_velocity.z == pytest.approx(GOOD_W[2] - 0.01, abs=1e-15)
        assert out.linear_acceleration.z == pytest.approx(9.81 / 1.01, abs=1e-12)
        assert g.node.diag.counts["non-finite sensor correction rejected"] == 1
    else:  # not subscribed: the strapdown applies them
        assert out.angular_velocity.z == GOOD_W[2] and out.linear_acceleration.z == 9.81


def test_calibration_file_and_temperature(graph, tmp_path):
    from sensor_msgs.msg import Temperature

    path = tmp_path / "imu_calibration.yaml"
    path.write_text(yaml.safe_dump({"imu_calibration": CAL.to_dict()}))
    g = graph(Parameter("calibration_file", value=str(path)),
              Parameter("use_temperature", value=True))
    w_true, f_true = np.array([0.1, -0.2, 0.3]), np.array([1.0, -2.0, 9.0])
    for k, temp in enumerate([25.0, np.nan, 55.0]):
        g.send("imu/temperature", Temperature(temperature=temp))
        g.imu(T0_NS + k * DT_NS, *CAL.simulate_raw(w_true, f_true, 55.0))
    assert g.node.diag.counts["non-finite temperature ignored"] == 1
    first, last = g.out["/imu/data"][0], g.out["/imu/data"][-1]
    np.testing.assert_allclose([last.angular_velocity.x, last.angular_velocity.y,
                                last.angular_velocity.z], w_true, atol=1e-12)
    # Read at the reference temperature the drift of 30 degC is not removed.
    assert abs(first.angular_velocity.x - w_true[0]) > 1e-3


@pytest.mark.parametrize("params, match", [
    ({"rate_hz": 300.0, "nav_rate_hz": 100.0, "coning_method": "two_sample"},
     "coning_method.*one_sample"),
    ({"calibration.gyro.bias": [0.1, 0.2]}, "calibration.gyro.bias.*multiple of 3"),
    ({"calibration.accel.nonorthogonality": [0.1] * 9}, "accel.nonorthogonality.*diagonal"),
    ({"calibration_file": "/nonexistent/cal.yaml"}, "calibration_file.*cannot read"),
    ({"calibration_file": "/tmp/x.yaml", "calibration.gyro.bias": [0.1, 0.0, 0.0]}, "not both"),
])
def test_bad_parameters_are_one_clear_error(ros_context, params, match):
    from ins_gnss_ros.nodes.base import ParameterError
    from ins_gnss_ros.nodes.imu_preprocessor_node import ImuPreprocessorNode

    with pytest.raises(ParameterError, match=match):
        ImuPreprocessorNode(context=ros_context,
                            parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])


def test_bad_calibration_file_content(ros_context, tmp_path):
    from ins_gnss_ros.nodes.base import ParameterError
    from ins_gnss_ros.nodes.imu_preprocessor_node import ImuPreprocessorNode

    path = tmp_path / "cal.yaml"
    path.write_text(yaml.safe_dump({"imu_calibration": {"gyro": {"bias": [1.0, 2.0]}}}))
    with pytest.raises(ParameterError, match="gyro.bias"):
        ImuPreprocessorNode(context=ros_context,
                            parameter_overrides=[Parameter("calibration_file", value=str(path))])
    path.write_text(yaml.safe_dump({"imu_calibration": {"mounting_rpy": [0, 0, 1.0]}}))
    with pytest.raises(ParameterError, match="mounting_rpy_deg.*one place"):
        ImuPreprocessorNode(context=ros_context, parameter_overrides=[
            Parameter("calibration_file", value=str(path)),
            Parameter("mounting_rpy_deg", value=[0.0, 0.0, 90.0])])


def test_publishes_over_ros(executor, ros_context, probe):
    from ins_gnss_msgs.msg import ImuDelta
    from sensor_msgs.msg import Imu

    from ins_gnss_ros.nodes.base import SENSOR_QOS
    from ins_gnss_ros.nodes.imu_preprocessor_node import ImuPreprocessorNode
    from rosutil import spin_until

    node = ImuPreprocessorNode(context=ros_context,
                               parameter_overrides=[Parameter("rate_hz", value=200.0)])
    executor.add_node(node)
    data, deltas = [], []
    probe.create_subscription(Imu, "imu/data", data.append, SENSOR_QOS)
    probe.create_subscription(ImuDelta, "imu/delta", deltas.append, SENSOR_QOS)
    pub = probe.create_publisher(Imu, "imu/data_raw", SENSOR_QOS)
    spin_until(executor, lambda: pub.get_subscription_count() > 0, what="imu/data_raw subscriber")
    for k in range(1, 5):
        pub.publish(_imu_msg(T0_NS + k * DT_NS, GOOD_W, G_UP))
    spin_until(executor, lambda: len(data) == 4 and len(deltas) == 2,
               what="4 imu/data, 2 imu/delta")
    assert deltas[-1].header.stamp.sec * NS + deltas[-1].header.stamp.nanosec == T0_NS + 4 * DT_NS
    assert deltas[-1].dt == pytest.approx(0.01)


def test_over_ros_at_1_khz_the_increments_are_the_bus_ones(executor, ros_context, probe, graph):
    """On DDS the raw samples are read from their payloads and, with nobody reading imu/data,
    those before an increment's last are handled together (nodes.base.Paced): the same
    increments as on the bus, bit for bit."""
    from ins_gnss_msgs.msg import ImuDelta
    from sensor_msgs.msg import Imu

    from ins_gnss_ros.nodes.base import SENSOR_QOS
    from ins_gnss_ros.nodes.imu_preprocessor_node import ImuPreprocessorNode
    from rosutil import spin_until

    params = _params(rate_hz=1000.0, max_identical_samples=0)
    node = ImuPreprocessorNode(context=ros_context, parameter_overrides=params)
    executor.add_node(node)
    deltas = []
    probe.create_subscription(ImuDelta, "imu/delta", deltas.append, SENSOR_QOS)
    pub = probe.create_publisher(Imu, "imu/data_raw", SENSOR_QOS)
    spin_until(executor, lambda: pub.get_subscription_count() > 0, what="imu/data_raw subscriber")
    g = graph(*params)
    rng = np.random.default_rng(3)
    for k in range(1, 41):
        msg = _imu_msg(T0_NS + k * 1_000_000, rng.normal(0.0, 0.1, 3),
                       G_UP + rng.normal(0.0, 0.1, 3))
        pub.publish(msg)
        g.send("imu/data_raw", msg)
    spin_until(executor, lambda: len(deltas) == 4, what="4 imu/delta")
    assert node.diag.traffic["received /imu/data_raw"] == 40
    for got, want in zip(deltas, g.out["/imu/delta"], strict=True):
        assert got.header.stamp == want.header.stamp and got.dt == want.dt
        for field in ("delta_angle", "delta_velocity"):
            a, b = getattr(got, field), getattr(want, field)
            assert (a.x, a.y, a.z) == (b.x, b.y, b.z)


def test_time_offset_moves_every_output_stamp(graph):
    from ins_gnss_ros.io import stamp_to_ns

    plain, shifted = graph(), graph(Parameter("time_offset_s", value=-0.125))
    for g in (plain, shifted):
        _run_stream(g, 10)
    for topic in ("/imu/data", "/imu/delta"):
        a = [stamp_to_ns(m.header.stamp) for m in plain.out[topic]]
        b = [stamp_to_ns(m.header.stamp) for m in shifted.out[topic]]
        assert a and b == [t - 125_000_000 for t in a]


def test_instant_samples_are_integrated_by_the_trapezoid_rule(graph):
    """A rate ramp w(t) = a t sampled at instants: the exact increment over [t-dt, t] is the
    trapezoid a (t - dt/2) dt; rate x dt would lag by half a sample."""
    from ins_gnss_ros.io import stamp_to_ns

    g = graph(Parameter("sample_model", value="instant"), Parameter("rate_hz", value=100.0),
              Parameter("coning_method", value="one_sample"))
    a, dt = 0.2, 0.01
    for k in range(1, 6):
        t_ns = T0_NS + k * 10_000_000
        g.imu(t_ns, [0.0, 0.0, a * (t_ns - T0_NS) / 1e9], G_UP)
    deltas = g.out["/imu/delta"][1:]  # the first has no neighbour before it
    for d in deltas:
        t = (stamp_to_ns(d.header.stamp) - T0_NS) / 1e9
        assert d.delta_angle.z == pytest.approx(a * (t - dt / 2) * dt, rel=1e-9)


def _jumping_clock_stream(g, paced, lost=False):
    """200 Hz samples arriving one period apart on the bus clock (or all at once if not
    ``paced``): the sensor stamps jump 0.5 s ahead after 1 s and back 1 s later. With ``lost``
    the samples of a 0.5 s stretch are missing instead (their arrivals too)."""
    for k in range(600):
        jump = 100 * DT_NS if 200 <= k < 400 else 0
        if lost and 200 <= k < 300:
            continue
        g.bus.now_ns = T0_NS + (k + 1) * DT_NS if paced else T0_NS
        g.imu(T0_NS + (k + 1) * DT_NS + (0 if lost else jump), GOOD_W, G_UP)


def test_clock_jump_is_taken_out_of_the_stamps_by_the_arrival_clock(graph):
    """Fault class clock_jump (IMU +0.5 s): samples that keep arriving at 200 Hz while their
    stamps jump 0.5 s ahead, then back, were not lost: both jumps are taken out of the stamps,
    so imu/delta keeps its 100 Hz step without a gap (before: a 0.5 s gap, 0.5 s ahead of the
    GNSS for 1 s, then 0.5 s of samples rejected as backwards)."""
    from ins_gnss_ros.io import stamp_to_ns

    g = graph()
    _jumping_clock_stream(g, paced=True)
    assert g.node.diag.counts["imu clock jump: stamps corrected by the arrival clock"] == 2
    stamps = np.array([stamp_to_ns(d.header.stamp) for d in g.out["/imu/delta"]])
    assert len(stamps) == 300
    np.testing.assert_array_equal(np.diff(stamps), 2 * DT_NS)
    assert stamps[-1] == T0_NS + 600 * DT_NS
    assert not any(k.startswith("imu sample rejected") or k.startswith("imu gap")
                   for k in g.node.diag.counts)


def test_samples_without_a_stamp_take_their_arrival_time(graph):
    """A driver that fills no header stamp (0): the samples were held for a rate that never
    measured, nothing was published, and the node said "ok"; now each takes its arrival time,
    counted on /diagnostics, and the magnetometer's samples too."""
    from sensor_msgs.msg import MagneticField

    from ins_gnss_ros.io import stamp_to_ns

    g = graph()
    for k in range(300):
        g.bus.now_ns = T0_NS + (k + 1) * DT_NS
        g.imu(0, GOOD_W, G_UP)
        if k % 4 == 0:
            g.send("imu/mag_raw", MagneticField())  # the magnetometer's stamps too
    stamps = np.array([stamp_to_ns(d.header.stamp) for d in g.out["/imu/delta"]])
    assert len(stamps) >= 140
    np.testing.assert_allclose(np.diff(stamps), 2 * DT_NS, atol=1000)
    assert stamps[-1] == pytest.approx(T0_NS + 300 * DT_NS, abs=1000)
    assert stamp_to_ns(g.out["/imu/mag"][-1].header.stamp) == T0_NS + 297 * DT_NS
    counts = g.node.diag.counts
    assert counts["imu/data_raw stamp unset (0): its arrival time used"] == 300
    assert counts["imu/mag_raw stamp unset (0): its arrival time used"] == 75


@pytest.mark.parametrize("paced, lost", [(False, False), (True, True)])
def test_gaps_and_unpaced_streams_are_not_clock_jumps(graph, paced, lost):
    """Samples delivered faster than real time on a clock that does not pace them (a replay on
    a wall clock, a burst) or really lost (their arrivals missing too) leave the stamps alone: the
    stamp jump reaches the strapdown and ekf as a gap, as before."""
    g = graph()
    _jumping_clock_stream(g, paced, lost)
    assert g.node.diag.counts["imu clock jump: stamps corrected by the arrival clock"] == 0
    assert g.node.diag.counts[
        "imu gap longer than max_bridge_samples: integration restarted"] == 1


def test_a_30_hz_imu_with_the_default_rates_is_measured_and_integrated(graph):
    """rate_hz 0 (the default): a 30 Hz IMU with nav_rate_hz 100 (before: "imu gap longer than
    max_bridge_samples" on every sample at the 200 Hz default, no imu/delta) is measured from
    its first stamps; every sample is then an increment, and /diagnostics says so."""
    g = graph(Parameter("rate_hz", value=0.0))
    period = NS / 30
    for k in range(1, 91):
        g.imu(T0_NS + round(k * period), GOOD_W, G_UP)
    assert len(g.out["/imu/data"]) == 90 and len(g.out["/imu/delta"]) == 90
    np.testing.assert_allclose([d.dt for d in g.out["/imu/delta"][1:]], 1 / 30, rtol=1e-6)
    assert not any(k.startswith("imu gap") for k in g.node.diag.counts)
    assert g.node.diag._values["rates"] == ("imu 30.0000 Hz, imu/delta 30.0000 Hz (one_sample), "
                                            "stamps scattered 0.0 ms RMS")


@pytest.mark.parametrize("enabled", [True, False])
def test_jittered_driver_stamps_are_replaced_by_the_sensor_clock(graph, enabled):
    """A 100 Hz IMU stamped by its driver with 2 ms uniform jitter: with the sensor clock the
    increments are stamped within 0.1 ms of the sampling instants after a few seconds and
    have their 20 ms step; without it they carry the jitter."""
    from ins_gnss_ros.io import stamp_to_ns

    g = graph(Parameter("rate_hz", value=0.0), Parameter("nav_rate_hz", value=50.0),
              Parameter("sensor_clock.enabled", value=enabled))
    rng = np.random.default_rng(5)
    truth = T0_NS + np.arange(1, 1001) * 10_000_000
    stamps = truth + np.round(rng.uniform(-1e6, 1e6, len(truth))).astype(np.int64)
    for t in stamps:
        g.imu(int(t), GOOD_W, G_UP)
    deltas = g.out["/imu/delta"]
    assert len(deltas) == 500
    ends = np.array([stamp_to_ns(d.header.stamp) for d in deltas])
    err = (ends - truth[1::2])[250:] / 1e9
    dt = np.array([d.dt for d in deltas])
    if enabled:
        assert abs(err).max() < 1e-4
        np.testing.assert_allclose(dt[250:], 0.02, atol=2e-5)   # raw: ±2 ms
    else:
        assert abs(err).max() > 5e-4 and dt.std() > 5e-4


@pytest.mark.parametrize("urdf_at", [None, 0, 20])
def test_a_urdf_s_mounting_is_taken_and_its_frame_not_published_twice(graph, urdf_at):
    """An IMU upside down in its frame imu_link, which a URDF places in base_link (rolled 180
    deg) on /tf_static before the first sample (``urdf_at`` 0) or after the first 20 (0.1 s:
    DDS matched the URDF's publisher after the IMU's): with no mounting given, the node takes
    that pose for every sample (gravity up in base_link; the early ones waited and none is
    lost) and does not publish its own imu_link transform, which would conflict with the
    URDF's. Without a URDF (None): the samples wait TF_WAIT_S for one, then go on in the axes
    as they come (gravity down), with its own transform published."""
    from ins_gnss_ros.io import ns_to_stamp
    from ins_gnss_ros.nodes.imu_preprocessor_node import TF_WAIT_S
    from ins_gnss_ros.nodes.tf_messages import static_tf

    g = graph()
    n = int(2 * TF_WAIT_S * NS / DT_NS)
    for k in range(n):
        if k == urdf_at:
            g.send("/tf_static", static_tf(ns_to_stamp(T0_NS), "base_link", [
                ("imu_link", (0.0, 0.0, 0.1), dcm_from_euler(np.pi, 0.0, 0.0))]))
        g.bus.now_ns = T0_NS + (k + 1) * DT_NS
        g.imu(T0_NS + (k + 1) * DT_NS, np.zeros(3), -G_UP, "imu_link")  # gravity along its -z
        if k == 19:  # before the URDF comes, or within the wait for it: nothing yet
            assert (len(g.out["/imu/delta"]) > 0) == (urdf_at == 0)
    up = [d.delta_velocity.z for d in g.out["/imu/delta"]]
    assert len(up) == n // 2  # none lost
    assert all((u > 0.0) == (urdf_at is not None) for u in up)
    mounting = g.node.diag._values["mounting"]
    assert mounting == ("[0, 0, 0] deg: /tf_static does not place imu/data_raw's frame "
                        "'imu_link' in 'base_link' (waited 1 s)" if urdf_at is None else
                        "[180.0, -0.0, 0.0] deg: /tf_static's pose of 'imu_link' in 'base_link'")
    assert (g.node.diag.counts["imu_link placed by another node's /tf_static: this node's "
                               "transform not published"] == 1) == (urdf_at is not None)
