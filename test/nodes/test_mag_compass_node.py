"""mag_compass node on the bus: a simulated steel mass is gated out, a hard/soft-iron calibration
from a tilted rotation gives the true heading, levelling fallback, bad input, parameters; in the
graph of the default profile on a simulated car drive, every heading once the filter has
corrected the strapdown and none before, and a disturbance still withheld."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pymap3d
import pytest
import yaml
from pygeomag import GeoMag
from rclpy.parameter import Parameter

from ins_gnss_ros.magnetic.compass import level_field, magnetic_azimuth
from ins_gnss_ros.magnetic.ellipsoid_fit import calibrate
from ins_gnss_ros.magnetic.wmm import decimal_year, field_elements
from ins_gnss_ros.nav.conventions import azimuth_from_yaw, wrap_pi
from ins_gnss_ros.nav.rotations import quat_from_euler, quat_to_euler
from ins_gnss_ros.sim.mag_sim import Dipole, MagErrors, simulate_magnetometer
from ins_gnss_ros.sim.trajectory import CarMotion, Route, generate
from ins_gnss_ros import io as bagio
from ins_gnss_ros.trial.replay import replay
from ins_gnss_ros.trial.simulate import simulate

REPO = Path(__file__).resolve().parents[2]

DEG = np.pi / 180
NS = 1_000_000_000
T0 = 1_780_000_000.0            # 2026-05-28 UTC: inside the WMM2025 life span
LAT0, LON0, H0 = 59.9 * DEG, 30.3 * DEG, 22.0
RATE = 10.0                     # magnetometer and ins/state rate, Hz
TILT_STD = 0.05 * DEG           # INS roll/pitch error (ISON-2 class)
FIELD_STD = 50e-9               # magnetometer noise per axis, T


def _stamp(t):
    from ins_gnss_ros.io import ns_to_stamp

    return ns_to_stamp(int(round((T0 + t) * 1e6)) * 1000)


def _key(stamp):
    return stamp.sec, stamp.nanosec


def _earth_field():
    return field_elements(LAT0, LON0, H0, decimal_year(T0))


class _Graph:
    """The compass on an InProcessBus fed from a simulation; records mag/heading."""

    def __init__(self, ros_context, params):
        from ins_gnss_ros.nodes.base import InProcessBus
        from ins_gnss_ros.nodes.mag_compass_node import MagCompassNode

        self.bus = InProcessBus()
        self.headings = []
        self.bus.subscribe("mag/heading", self.headings.append)
        self.node = MagCompassNode(context=ros_context, bus=self.bus,
                                   parameter_overrides=[Parameter(k, value=v)
                                                        for k, v in params.items()])

    def send(self, topic, msg):
        self.bus.publish(topic, msg)
        self.bus.drain()

    def mag(self, t, m):
        from sensor_msgs.msg import MagneticField

        from ins_gnss_ros.nodes.convert import to_vector3

        msg = MagneticField(magnetic_field=to_vector3(m))
        msg.header.stamp = _stamp(t)
        self.send("imu/mag", msg)

    def ins(self, t, roll, pitch, yaw, lat=LAT0, lon=LON0, h=H0):
        from ins_gnss_msgs.msg import InsState

        from ins_gnss_ros.nodes.convert import to_quaternion

        msg = InsState(latitude=float(lat), longitude=float(lon), altitude=float(h),
                       orientation=to_quaternion(quat_from_euler(roll, pitch, yaw)),
                       mode=InsState.MODE_NAVIGATING)
        msg.header.stamp = _stamp(t)
        self.send("ins/state", msg)

    def replay(self, traj, meas, seed=1):
        """ins/state (truth + tilt noise) before each magnetometer sample; the stamp of each
        published heading and the true azimuth at it."""
        rng = np.random.default_rng(seed)
        k_of = {round(t * RATE): k for k, t in enumerate(traj.t)}
        truth = {}
        for t, m in zip(meas.t, meas.field_b):
            k = k_of[round(t * RATE)]
            r, p, y = traj.rpy[k]
            self.ins(t, r + rng.normal(0, TILT_STD), p + rng.normal(0, TILT_STD), y,
                     traj.lat[k], traj.lon[k], traj.h[k])
            self.mag(t, m)
            truth[_key(_stamp(t))] = azimuth_from_yaw(y)
        return truth

    def close(self):
        if self.node is not None:
            self.node.destroy_node()
            self.node = None


@pytest.fixture
def graph(ros_context):
    graphs = []

    def make(**params):
        # The fallback position is the simulation's start, so the WMM agrees with _earth_field.
        g = _Graph(ros_context, {"position.altitude_m": H0, **params})
        graphs.append(g)
        return g
    yield make
    for g in graphs:
        g.close()


def _errors(g, truth):
    return np.array([wrap_pi(h.azimuth - truth[_key(h.header.stamp)]) for h in g.headings])


def test_steel_mass_is_gated_out_for_the_whole_stop(graph):
    """A car heading north drives up to a truck (a dipole 3 m to its left), waits 30 s beside it
    and drives on: no heading disturbed beyond the noise may reach mag/heading while it stands
    beside the truck, and hardly any on the way there."""
    route = Route(yaw0=90 * DEG).hold(20.0).change_speed(8.0, 2.0).hold(8.0)
    route.stop(30.0, decel=2.0).change_speed(8.0, 2.0).hold(20.0)
    traj = generate(CarMotion(route), LAT0, LON0, H0, route.t, RATE, oversample=2)
    speed = np.linalg.norm(traj.v_enu, axis=1)
    stopped = np.flatnonzero((speed < 1e-6) & (traj.t > 30.0))
    k_stop = stopped[len(stopped) // 2]
    yaw = traj.rpy[k_stop, 2]
    left = np.array([-np.sin(yaw), np.cos(yaw), 0.0])
    e, n, u = pymap3d.geodetic2enu(traj.lat[k_stop], traj.lon[k_stop], traj.h[k_stop],
                                   LAT0, LON0, H0, deg=False)
    truck = pymap3d.enu2geodetic(*(np.array([e, n, u]) + 3.0 * left), LAT0, LON0, H0, deg=False)
    # Beside the car the horizontal moment gives 2.2 uT to the east (a 8.5 deg turn of the field),
    # the vertical one 0.7 uT up (what changes |F| and the dip).
    dipole = Dipole(*truck, moment_enu=(300.0, 0.0, -200.0))
    wmm = _earth_field()
    meas = simulate_magnetometer(traj, wmm.enu, MagErrors(noise_std=FIELD_STD), RATE, seed=3,
                                 dipoles=[dipole])
    # What the truck does to a compass: the turn of the horizontal field (independent of tilt).
    h_earth = wmm.enu[:2]
    h_dist = h_earth + meas.disturbance_n[:, :2]
    turn = np.abs(wrap_pi(np.arctan2(h_dist[:, 1], h_dist[:, 0])
                          - np.arctan2(h_earth[1], h_earth[0])))
    g = graph(**{"field_std_nT": FIELD_STD * 1e9})
    truth = g.replay(traj, meas)
    published = {_key(h.header.stamp) for h in g.headings}
    is_pub = np.array([_key(_stamp(t)) in published for t in meas.t])
    disturbed = turn > 1.0 * DEG
    err = _errors(g, truth)
    sigma = np.sqrt(np.mean([h.azimuth_variance for h in g.headings]))
    print(f"\ntruck beside the car: max heading turn {np.degrees(turn.max()):.1f} deg, "
          f"{disturbed.sum() / RATE:.1f} s turned > 1 deg, {np.sum(disturbed & is_pub)} of them "
          f"published (largest published turn {np.degrees(turn[is_pub].max()):.2f} deg); withheld "
          f"{np.sum(~is_pub) / RATE:.1f} s; published heading error RMS "
          f"{np.degrees(np.sqrt(np.mean(err ** 2))):.3f} deg, max {np.degrees(abs(err).max()):.3f}"
          f" deg (1 sigma from the node {np.degrees(sigma):.3f} deg)")
    assert turn.max() > 5 * DEG and disturbed.sum() / RATE >= 30.0
    # The detector sees |F| and the dip, not the turn of the horizontal field: as the truck comes
    # near, the turn grows ahead of them and a few samples turned by 1-2 deg get through before
    # the flag rises (over 30 noise seeds: none in 12, at most 3 samples and 2.2 deg; with the
    # running averages started from their first sample none in 5 of the 30, this seed one of them).
    onset = disturbed & is_pub
    t_stop = traj.t[stopped[0]]
    assert onset.sum() <= 3 and np.all(meas.t[onset] < t_stop) and turn[is_pub].max() < 2.5 * DEG
    assert not np.any(is_pub[turn > 0.5 * turn.max()])
    index = {_key(_stamp(t)): i for i, t in enumerate(meas.t)}
    clean = np.array([not disturbed[index[_key(h.header.stamp)]] for h in g.headings])
    assert np.max(np.abs(err[clean])) < 4.5 * sigma
    assert g.node.diag.counts["magnetic disturbance: heading withheld"] >= 30 * RATE
    assert is_pub[: int(25 * RATE)].all() and is_pub[-int(5 * RATE):].all()  # before and after
    assert {h.source for h in g.headings} == {g.headings[0].SOURCE_MAGNETIC}


def _tilted_rotation(banks, pitches, seed):
    """Circles at 10 m/s, each with its own bank and pitch; magnetometer with hard/soft iron."""
    route = Route(yaw0=0.0, speed0=10.0, ramp=1.0)
    for bank, pitch in zip(banks, pitches):
        route.set_bank(bank, 2.0).set_pitch(pitch, 2.0).hold(3.0)
        route.circle(radius=40.0)
    traj = generate(CarMotion(route, roll_gain=0.0), LAT0, LON0, H0, route.t, RATE, oversample=2)
    errors = MagErrors(hard_iron_b=np.array([8e-6, -5e-6, 12e-6]),
                       soft_iron=np.array([[0.08, 0.03, -0.02], [0.03, -0.06, 0.01],
                                           [-0.02, 0.01, 0.04]]),
                       noise_std=FIELD_STD)
    return traj, simulate_magnetometer(traj, _earth_field().enu, errors, RATE, seed=seed)


def test_heading_after_calibration_on_a_tilted_rotation(graph, tmp_path):
    cal_traj, cal_meas = _tilted_rotation([0.0, 0.25, -0.25, 0.0, 0.0],
                                          [0.0, 0.0, 0.0, 0.2, -0.2], 5)
    k = np.round(cal_meas.t * RATE).astype(int)
    hsi = calibrate(cal_meas.field_b, _earth_field().total, cal_traj.rpy[k, 0], cal_traj.rpy[k, 1])
    path = tmp_path / "mag_calibration.yaml"
    path.write_text(yaml.safe_dump({"mag_calibration": hsi.to_dict()}))
    # A different run: tilted 15 deg right and 8 deg nose up, then 10 deg left and nose down.
    traj, meas = _tilted_rotation([15 * DEG, -10 * DEG], [-8 * DEG, 6 * DEG], 6)
    rms = {}
    for name, params in (("uncalibrated", {}), ("calibrated", {"calibration_file": str(path)})):
        g = graph(**params, **{"field_std_nT": FIELD_STD * 1e9,
                               "disturbance.model_total_tol": 10.0,
                               "disturbance.model_inclination_deg": 90.0,
                               "disturbance.running_total_tol": 10.0,
                               "disturbance.running_inclination_deg": 90.0})
        err = _errors(g, g.replay(traj, meas))
        g.close()  # one compass at a time: they share the node name
        assert len(err) == len(meas.t)
        rms[name] = np.sqrt(np.mean(err ** 2))
    sigma = np.sqrt(np.mean([h.azimuth_variance for h in g.headings]))
    print(f"\ntilted rotation (15/-10 deg roll, -8/6 deg pitch): heading RMS uncalibrated "
          f"{np.degrees(rms['uncalibrated']):.2f} deg, calibrated "
          f"{np.degrees(rms['calibrated']):.3f} deg, node 1 sigma {np.degrees(sigma):.3f} deg")
    assert rms["uncalibrated"] > 10 * DEG
    assert rms["calibrated"] < 1.3 * sigma


def test_true_and_magnetic_reference_and_declination_from_the_fix(graph):
    from sensor_msgs.msg import NavSatFix, NavSatStatus

    lat, lon = 45.0, -100.0  # the fix moves the compass far from the fallback position
    model = GeoMag(coefficients_file="wmm/WMM_2025.COF")
    r = model.calculate(glat=lat, glon=lon, alt=0.3, time=decimal_year(T0))
    decl = r.d * DEG
    h_enu = np.array([np.sin(decl), np.cos(decl), 0.0]) * r.h * 1e-9
    field_enu = h_enu + np.array([0, 0, -r.z * 1e-9])
    yaw = 30 * DEG  # body x axis 60 deg east of true north, level
    c_bn = np.linalg.inv(np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0],
                                   [0, 0, 1]]))
    out = {}
    for ref in ("true", "magnetic"):
        g = graph(reference=ref)
        fix = NavSatFix(latitude=lat, longitude=lon, altitude=300.0)
        fix.status.status = NavSatStatus.STATUS_FIX
        g.send("gnss/fix", fix)
        g.ins(0.0, 0.0, 0.0, yaw)
        g.mag(0.01, c_bn @ field_enu)
        out[ref] = g.headings[-1]
        g.close()
    assert out["true"].reference == out["true"].REFERENCE_TRUE
    assert out["magnetic"].reference == out["magnetic"].REFERENCE_MAGNETIC
    assert out["true"].azimuth == pytest.approx(60 * DEG, abs=1e-9)
    assert out["magnetic"].azimuth == pytest.approx(60 * DEG - decl, abs=1e-9)
    assert out["true"].declination == pytest.approx(decl, abs=1e-9)
    assert np.isnan(out["true"].pitch) and np.isnan(out["true"].roll)


def test_levelling_fallback_from_imu_data(graph):
    from sensor_msgs.msg import Imu

    from ins_gnss_ros.nodes.convert import to_vector3

    roll, pitch, yaw = 12 * DEG, -7 * DEG, 200 * DEG
    c_bn = np.linalg.inv(np.asarray(_rot(roll, pitch, yaw)))
    wmm = _earth_field()
    g = graph(attitude_source="imu_data", level_time_constant_s=0.5, roll_std_deg=0.5,
              pitch_std_deg=0.5)
    for k in range(30):
        imu = Imu(linear_acceleration=to_vector3(c_bn @ [0.0, 0.0, 9.81]))
        imu.header.stamp = _stamp(k * 0.01)
        g.send("imu/data", imu)
    g.mag(0.3, c_bn @ wmm.enu)
    assert len(g.headings) == 1
    assert g.headings[0].azimuth == pytest.approx(float(azimuth_from_yaw(yaw)), abs=1e-9)


def _rot(roll, pitch, yaw):
    """Rz(yaw) Ry(pitch) Rx(roll), written out by hand."""
    cr, sr, cp, sp, cy, sy = (np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch),
                              np.cos(yaw), np.sin(yaw))
    rz = [[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]]
    ry = [[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]]
    rx = [[1, 0, 0], [0, cr, -sr], [0, sr, cr]]
    return np.array(rz) @ np.array(ry) @ np.array(rx)


def test_bad_input_is_counted_and_no_heading_from_it(graph):
    from ins_gnss_msgs.msg import InsState
    from sensor_msgs.msg import NavSatFix, NavSatStatus

    wmm = _earth_field()
    m = wmm.enu  # level, yaw 0: body = ENU
    g = graph()
    no_fix = NavSatFix(latitude=10.0, longitude=10.0)  # not a fix: the position must not move
    no_fix.status.status = NavSatStatus.STATUS_NO_FIX
    g.send("gnss/fix", no_fix)
    g.mag(0.0, m)                                   # no attitude yet
    g.ins(0.1, 0.0, 0.0, 0.0)
    g.mag(0.1, [np.nan, 0.0, 0.0])                  # non-finite
    g.mag(0.12, m)                                  # good
    g.mag(0.12, m)                                  # duplicate stamp
    g.mag(0.05, m)                                  # backwards
    g.mag(5.0, m)                                   # attitude 4.9 s old
    bad = InsState(mode=InsState.MODE_NAVIGATING)   # zero quaternion
    bad.orientation.w = 0.0
    bad.header.stamp = _stamp(5.0)
    g.send("ins/state", bad)
    g.mag(5.01, m)
    counts = g.node.diag.counts
    assert counts["no roll/pitch within max_attitude_age_s: heading withheld"] == 3
    assert counts["magnetometer sample rejected: non_finite"] == 1
    assert counts["magnetometer sample rejected: stamp not after the previous one"] == 2
    assert counts["invalid ins/state ignored"] == 1
    assert counts["gnss/fix without a valid position ignored"] == 1
    assert len(g.headings) == 1 and g.headings[0].azimuth == pytest.approx(np.pi / 2, abs=1e-9)


def test_heading_from_every_ins_state_a_filter_has_levelled(graph):
    """The strapdown says the filter's mode: ALIGNING after the first correction (levelled at
    rest, heading unknown) and DEAD_RECKONING (degraded) both come with a levelled attitude
    (as level as the filter's tilt sigma on nav/status says); only a state no filter has
    corrected (sequence 0) has none."""
    from ins_gnss_msgs.msg import FilterStatus, InsState

    from ins_gnss_ros.nodes.convert import to_quaternion

    m = _earth_field().enu  # level, yaw 0: body = ENU
    g = graph()
    g.send("nav/status", FilterStatus(state_names=["att[0]", "att[1]", "att[2]"],
                                      state_std=[1e-3, 1e-3, 1e-2]))
    for k, (mode, sequence) in enumerate([(InsState.MODE_ALIGNING, 0),
                                          (InsState.MODE_ALIGNING, 1),
                                          (InsState.MODE_DEAD_RECKONING, 2),
                                          (InsState.MODE_NAVIGATING, 3)]):
        state = InsState(latitude=LAT0, longitude=LON0, altitude=H0, mode=mode,
                         correction_sequence=sequence,
                         orientation=to_quaternion([1.0, 0.0, 0.0, 0.0]))
        state.header.stamp = _stamp(0.1 * k)
        g.send("ins/state", state)
        g.mag(0.1 * k + 0.01, m)
    assert g.node.diag.counts["ins/state not corrected by a filter yet (roll/pitch unknown): "
                              "heading withheld"] == 1
    assert [_key(h.header.stamp) for h in g.headings] == \
        [_key(_stamp(0.1 * k + 0.01)) for k in (1, 2, 3)]
    assert all(h.azimuth == pytest.approx(np.pi / 2, abs=1e-9) for h in g.headings)


def test_wmm_outside_its_life_span_withholds_heading(graph):
    g = graph(decimal_year=2035.0)
    g.ins(0.0, 0.0, 0.0, 0.0)
    g.mag(0.01, _earth_field().enu)
    assert not g.headings
    assert any(k.startswith("WMM unavailable") for k in g.node.diag.counts)


@pytest.mark.parametrize("params, match", [
    ({"calibration_file": "/nonexistent/mag.yaml"}, "calibration_file.*cannot read"),
    ({"calibration.soft_iron": [-1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]}, "determinant"),
    ({"calibration_file": "/tmp/x.yaml", "calibration.heading_bias_deg": 1.0}, "not both"),
    ({"reference": "grid"}, "reference"),
])
def test_bad_parameters_are_one_clear_error(ros_context, params, match):
    from rclpy.exceptions import InvalidParameterValueException

    from ins_gnss_ros.nodes.base import ParameterError
    from ins_gnss_ros.nodes.mag_compass_node import MagCompassNode

    with pytest.raises((ParameterError, InvalidParameterValueException), match=match):
        MagCompassNode(context=ros_context,
                       parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])


def test_calibration_file_with_heading_bias(graph, tmp_path):
    path = tmp_path / "mag.yaml"
    path.write_text(yaml.safe_dump({"mag_calibration": {
        "hard_iron": [1e-6, 2e-6, -3e-6], "soft_iron": np.eye(3).tolist(), "heading_bias": 0.02}}))
    g = graph(calibration_file=str(path), reference="magnetic")
    wmm = _earth_field()
    g.ins(0.0, 0.0, 0.0, 0.0)
    g.mag(0.01, wmm.enu + [1e-6, 2e-6, -3e-6])
    expected = azimuth_from_yaw(0.0) - wmm.declination - 0.02
    assert g.headings[0].azimuth == pytest.approx(float(expected), abs=1e-9)


def test_publishes_over_ros(executor, ros_context, probe):
    from ins_gnss_msgs.msg import Heading, InsState
    from sensor_msgs.msg import MagneticField

    from ins_gnss_ros.nodes.base import SENSOR_QOS
    from ins_gnss_ros.nodes.convert import to_quaternion, to_vector3
    from ins_gnss_ros.nodes.mag_compass_node import MagCompassNode
    from rosutil import spin_until

    node = MagCompassNode(context=ros_context)
    executor.add_node(node)
    headings = []
    probe.create_subscription(Heading, "mag/heading", headings.append, SENSOR_QOS)
    pub_ins = probe.create_publisher(InsState, "ins/state", SENSOR_QOS)
    pub_mag = probe.create_publisher(MagneticField, "imu/mag", SENSOR_QOS)
    spin_until(executor, lambda: pub_ins.get_subscription_count() > 0
               and pub_mag.get_subscription_count() > 0, what="compass subscriptions")
    state = InsState(orientation=to_quaternion([1.0, 0.0, 0.0, 0.0]), mode=InsState.MODE_NAVIGATING,
                     latitude=LAT0, longitude=LON0, altitude=H0)
    state.header.stamp = _stamp(0.0)
    pub_ins.publish(state)
    # taken as serialized bytes and decoded with the next field sample
    spin_until(executor, lambda: node.ins_state.waiting, what="ins/state")
    mag = MagneticField(magnetic_field=to_vector3(_earth_field().enu))
    mag.header.stamp = _stamp(0.05)
    pub_mag.publish(mag)
    spin_until(executor, lambda: len(headings) == 1, what="mag/heading")
    assert headings[0].azimuth == pytest.approx(np.pi / 2, abs=1e-9)  # x axis east
    assert headings[0].header.stamp == _stamp(0.05)
    # counted when taken, from a subscription no executor dispatches
    assert node.diag.traffic["taken /ins/state"] == 1
    assert "/ins/state" not in {sub.topic_name for sub in node.subscriptions}


#: The simulated drive of bench/bench_identity.py (sim_car): MEMS IMU, 50 Hz magnetometer with
#: 100 nT of noise; the ekf levels at the first fix (1.2 s) and knows the tilt to 0.3-1 deg.
DRIVE_S, DRIVE_SEED = 60.0, 3
#: A field switched on at the sensor (a magnet, a cable): 3 uT to the left and 3 uT down raise
#: |F| by 5 % and turn the heading by up to 11 deg.
DISTURBANCE = {"kind": "magnetic_disturbance", "start": 30.0, "duration": 10.0,
               "field_t": [0.0, 3e-6, -3e-6]}


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """The drive replayed through config/default.yaml (the replay leaves the sensor sources
    out) with the simulated sensor's calibration (the identity: an ideal sensor) given as one
    from an earlier run, clean and with DISTURBANCE."""
    root = tmp_path_factory.mktemp("compass_drive")
    bag = simulate("car", DRIVE_S, DRIVE_SEED, root / "car")
    calibration = root / "identity.yaml"
    calibration.write_text(yaml.safe_dump({"mag_calibration": {"hard_iron": [0.0] * 3}}))
    profile = yaml.safe_load((REPO / "config" / "default.yaml").read_text())
    profile["mag_compass"]["ros__parameters"]["calibration_file"] = str(calibration)
    profile_path = root / "profile.yaml"
    profile_path.write_text(yaml.safe_dump(profile))
    profile = profile_path
    faults = root / "faults.yaml"
    faults.write_text(yaml.safe_dump({"faults": [DISTURBANCE]}))
    replay(bag, profile, root / "clean")
    replay(bag, profile, root / "disturbed", faults=faults)
    return {"truth": bag, "clean": root / "clean" / "bag", "disturbed": root / "disturbed" / "bag"}


def _by_stamp(path, topic):
    return {bagio.msg_stamp_ns(m.msg): m.msg for m in bagio.read_bag(path, [topic])}


def test_clean_drive_every_heading_once_the_filter_has_corrected_the_strapdown(drive):
    states = sorted(_by_stamp(drive["clean"], "ins/state").items())
    # The strapdown stamps from float seconds: its stamps are a few ns off the magnetometer's.
    known_ns = next(t for t, s in states if s.correction_sequence > 0) - 1000
    mag = _by_stamp(drive["clean"], "imu/mag")
    headings = _by_stamp(drive["clean"], "mag/heading")
    after = [t for t in mag if t >= known_ns]
    # Before the first correction the strapdown's attitude is its initial parameters: however
    # level the simulated car starts, no heading may come from it.
    assert headings and min(headings) >= known_ns
    assert len(headings) >= 0.99 * len(after)
    truth = _by_stamp(drive["truth"], "truth/state")
    ratio = [abs(wrap_pi(h.azimuth - azimuth_from_yaw(quat_to_euler(_quat(truth[t]))[2])))
             / np.sqrt(h.azimuth_variance) for t, h in headings.items() if t in truth]
    print(f"\nclean drive: {len(headings)} of the {len(after)} magnetometer samples after the "
          f"first correction at {(known_ns - min(mag)) / NS:.2f} s published; largest error "
          f"{max(ratio):.2f} sigma at {len(ratio)} truth epochs")
    assert len(ratio) > 500 and max(ratio) < 4.0


def test_disturbance_on_the_drive_is_withheld_and_headings_resume(drive):
    clean = _by_stamp(drive["clean"], "imu/mag")
    disturbed = _by_stamp(drive["disturbed"], "imu/mag")
    headings = _by_stamp(drive["disturbed"], "mag/heading")
    states = sorted(_by_stamp(drive["disturbed"], "ins/state").items())
    t_ns = np.array(sorted(clean))
    k = np.searchsorted([t for t, _ in states], t_ns, side="right") - 1
    roll, pitch = np.array([quat_to_euler(_quat(states[i][1]))[:2] for i in k]).T
    # What the field does to a compass that does not gate it.
    turn = np.array([wrap_pi(magnetic_azimuth(_vec(disturbed[t]), r, p)
                             - magnetic_azimuth(_vec(clean[t]), r, p))
                     for t, r, p in zip(t_ns, roll, pitch)])
    on = np.abs(turn) > 1e-9
    is_pub = np.array([t in headings for t in t_ns])
    s_on, s_off = (t_ns[on][[0, -1]] - t_ns[0]) / NS
    resumed = is_pub[t_ns >= t_ns[on][-1] + 3 * NS]
    print(f"\ndisturbance {s_on:.1f}-{s_off:.1f} s: heading turned up to "
          f"{np.degrees(np.abs(turn).max()):.1f} deg, {is_pub[on].sum()} of {on.sum()} samples "
          f"published; {resumed.mean():.1%} published from 3 s after it")
    assert np.degrees(np.abs(turn).max()) > 5.0 and on.sum() >= 0.9 * DISTURBANCE["duration"] * 50
    assert not is_pub[on].any()
    assert resumed.mean() > 0.99


def _quat(state):
    o = state.orientation
    return np.array([o.w, o.x, o.y, o.z])


def _vec(msg):
    f = msg.magnetic_field
    return np.array([f.x, f.y, f.z])


def test_a_field_without_a_stamp_takes_its_arrival_time(graph):
    """imu/mag from a driver that fills no header stamp (0) is read at its arrival: a heading
    comes from it, counted on /diagnostics."""
    from sensor_msgs.msg import MagneticField

    from ins_gnss_ros.io import stamp_to_ns
    from ins_gnss_ros.nodes.convert import to_vector3

    g = graph()
    g.ins(1.0, 0.0, 0.0, 0.0)
    g.bus.now_ns = stamp_to_ns(_stamp(1.02))
    g.send("imu/mag", MagneticField(magnetic_field=to_vector3(_earth_field().enu)))
    assert len(g.headings) == 1 and stamp_to_ns(g.headings[0].header.stamp) == g.bus.now_ns
    assert g.node.diag.counts["imu/mag stamp unset (0): its arrival time used"] == 1
