"""``trial import`` on the recorded data in ../shared (skipped when it is absent).

Truth is read straight from the source files with other parsers: pandas for the parquet, the
raw bytes of the RTKLIB tag file (struct), the text of the .pos file, pyubx2 for the u-blox
stream, plus physics (gravity along base_link z when the car stands still).
"""
import math
import struct

import numpy as np
import pandas as pd
import pytest
from conftest import REPO, shared_path
from scipy.spatial.transform import Rotation

from ins_gnss_ros import io as bagio
from ins_gnss_ros.trial.importers import (car_mounting_rpy_deg, import_rtklib_drive, import_ubx,
                                          import_vessel_parquet)


def _topic(messages, topic):
    return [m.msg for m in messages if m.topic == topic]


@pytest.fixture(scope="module")
def vessel(tmp_path_factory):
    src = shared_path("data", "vessel_waves", "ains_ahrs_imu.parquet")
    out = import_vessel_parquet(src, tmp_path_factory.mktemp("imp") / "vessel")
    return pd.read_parquet(src), bagio.read_bag(out)


#: IMU rows of the car log kept for the tests (the first minute; the full import takes longer).
CAR_ROWS = 6000


@pytest.fixture(scope="module")
def car(tmp_path_factory):
    """The car folder with its IMU log cut to the first minute (tag and .pos files whole: the
    tag mapping then spreads the minute over the whole drive, which these tests do not use)."""
    import shutil

    full = shared_path("data", "car_drive_0708")
    src = tmp_path_factory.mktemp("car_src")
    for name in ("imu_1934.csv.tag", "gnss_1934_sf.pos"):
        shutil.copy(full / name, src / name)
    lines = (full / "imu_1934.csv").read_text().splitlines(keepends=True)
    (src / "imu_1934.csv").write_text("".join(lines[:CAR_ROWS]))
    return src, bagio.read_bag(import_rtklib_drive(src, tmp_path_factory.mktemp("imp") / "car"))


def test_vessel_topics_counts_and_rate(vessel):
    frame, messages = vessel
    n = len(frame)
    for topic in ("/imu/data_raw", "/gnss/fix", "/gnss/heading", "/truth/state",
                  "/truth/heading"):
        assert len(_topic(messages, topic)) == n, topic
    t = np.array([m.t_ns for m in messages if m.topic == "/imu/data_raw"])
    assert np.allclose(np.diff(t), 1e9 / 10.24, atol=1)


def test_vessel_compass_heading_and_imu_axes(vessel):
    frame, messages = vessel
    headings = _topic(messages, "/gnss/heading")
    expected = np.radians(frame["Gamma_meas"].to_numpy()) % (2 * np.pi)
    assert np.allclose([h.azimuth for h in headings], expected, atol=1e-12)
    h = headings[0]
    assert h.reference == h.REFERENCE_TRUE and h.source == h.SOURCE_RECEIVER
    assert h.azimuth_variance == pytest.approx(math.radians(0.1) ** 2)
    imu = _topic(messages, "/imu/data_raw")
    # FRD -> FLU: y and z change sign.
    assert imu[5].linear_acceleration.z == pytest.approx(-frame["Az_meas"].iloc[5])
    assert imu[5].angular_velocity.y == pytest.approx(-math.radians(frame["Gy_meas"].iloc[5]))


def test_car_imu_is_raw_sensor_axes_stamped_by_the_tag_file(car):
    src, messages = car
    imu = _topic(messages, "/imu/data_raw")
    rows = (src / "imu_1934.csv").read_text().splitlines()
    first = [float(v) for v in rows[0].split(",")]  # this log has no header line
    assert imu[0].linear_acceleration.x == pytest.approx(first[0] * 9.80665)
    assert imu[0].angular_velocity.z == pytest.approx(math.radians(first[5]))
    assert len(imu) == CAR_ROWS
    raw = (src / "imu_1934.csv.tag").read_bytes()
    _tick_f, time_time, time_sec = struct.unpack_from("<IId", raw, 60)
    t_first = next(m.t_ns for m in messages if m.topic == "/imu/data_raw")
    # The tag counts GPS time like Unix time (RTKLIB gtime_t); the bag is on the UTC axis, 18
    # leap seconds earlier in 2025. The -0.125 s IMU offset is NOT applied.
    assert t_first == pytest.approx((time_time + time_sec - 18) * 1e9, abs=1e3)


def test_car_mounting_puts_gravity_on_base_link_z(car):
    _, messages = car
    imu = _topic(messages, "/imu/data_raw")[:200]  # the first 2 s: the car stands still
    f = np.mean([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z]
                 for m in imu], axis=0)
    f_base = Rotation.from_euler("ZYX", car_mounting_rpy_deg()[::-1], degrees=True).apply(f)
    # Direction only: this MEMS unit reads |f| = 1.01 g at rest (its scale/bias error).
    tilt = math.degrees(math.atan2(math.hypot(f_base[0], f_base[1]), f_base[2]))
    assert tilt < 3.0  # up along base_link z, a parked car on a modest grade


def test_car_gnss_and_truth_from_the_pos_file(car):
    src, messages = car
    lines = [ln for ln in (src / "gnss_1934_sf.pos").read_text().splitlines()
             if ln and not ln.startswith("%")]
    fields = lines[0].split()
    fixes = _topic(messages, "/gnss/fix")
    assert len(fixes) == len(lines)
    assert fixes[0].latitude == pytest.approx(float(fields[2]), abs=1e-9)
    assert fixes[0].longitude == pytest.approx(float(fields[3]), abs=1e-9)
    # the file holds hMSL; the bag ellipsoidal height (car_drive.SITE_GEOID_SEPARATION_M)
    assert fixes[0].altitude == pytest.approx(float(fields[4]) - 21.387, abs=1e-4)
    q_fixed = sum(1 for ln in lines if float(ln.split()[5]) == 1.0)
    truth = _topic(messages, "/truth/state")
    assert len(truth) == q_fixed
    assert math.isnan(truth[0].orientation.w)  # no attitude truth in this data set
    assert len(_topic(messages, "/gnss/vel")) == len(lines)


def test_ubx_observations_ephemeris_and_fix(tmp_path):
    from pyubx2 import UBXReader

    full = shared_path("data", "walk_0827", "gnss_1730.ubx")
    # The first ~40 % of the walk (the decoder's time dominates): ends mid-frame, as a cut
    # stream does.
    src = tmp_path / "walk.ubx"
    src.write_bytes(full.read_bytes()[:600_000])
    messages = bagio.read_bag(import_ubx(src, tmp_path / "walk",
                                         truth_pos=full.with_name("gnss_1730_sf.pos")))
    observations = _topic(messages, "/gnss/observations")
    with open(src, "rb") as f:
        raws = [msg for _raw, msg in UBXReader(f, protfilter=2, quitonerror=0)
                if msg is not None and msg.identity == "RXM-RAWX"]
    assert len(observations) == len(raws) > 150
    first, obs = raws[0], observations[0]
    assert obs.gps_week == first.week and obs.time_of_week == pytest.approx(first.rcvTow)
    assert len(obs.pseudorange) == first.numMeas
    assert obs.pseudorange[0] == pytest.approx(first.prMes_01)
    assert obs.carrier_phase[0] == pytest.approx(first.cpMes_01)
    ephemerides = _topic(messages, "/gnss/ephemeris")
    assert len(ephemerides) > 5
    gps = [e for e in ephemerides if e.system == 0]
    assert gps and all(5100 < e.sqrt_a < 5200 for e in gps)  # GPS orbit radius ~26560 km
    assert len(_topic(messages, "/gnss/fix")) > 150
    assert len(_topic(messages, "/truth/state")) > 0


def test_ubx_truth_with_the_rtk_float_epochs(tmp_path):
    folder = shared_path("data", "walk_0827")
    src = tmp_path / "walk.ubx"
    src.write_bytes((folder / "gnss_1730.ubx").read_bytes()[:20_000])
    pos = folder / "gnss_1730_sf.pos"
    lines = [ln for ln in pos.read_text().splitlines() if ln and not ln.startswith("%")]
    rtk = [ln for ln in lines if float(ln.split()[5]) in (1.0, 2.0)]
    messages = bagio.read_bag(import_ubx(src, tmp_path / "walk", truth_pos=pos,
                                         truth_float=True))
    truth = _topic(messages, "/truth/state")
    assert len(rtk) > sum(float(ln.split()[5]) == 1.0 for ln in lines) and len(truth) == len(rtk)
    last = rtk[-1].split()
    assert math.degrees(truth[-1].latitude) == pytest.approx(float(last[2]), abs=1e-9)


def test_walk_imu_beside_the_ubx_stream(tmp_path):
    """The walk's IMU log (cut first line) goes into the u-blox bag in its own axes, stamped by
    its tag file; config/walk.yaml's mounting puts the still start's gravity on base_link z."""
    import yaml

    folder = shared_path("data", "walk_0827")
    src = tmp_path / "walk.ubx"
    src.write_bytes((folder / "gnss_1730.ubx").read_bytes()[:20_000])  # a few GNSS epochs
    messages = bagio.read_bag(import_ubx(src, tmp_path / "walk",
                                         imu_csv=folder / "imu_1730.csv"))
    imu = _topic(messages, "/imu/data_raw")
    lines = (folder / "imu_1730.csv").read_text().splitlines()
    whole = [ln for ln in lines if len(ln.split(",")) == 7]
    assert len(lines[0].split(",")) < 7 and len(imu) == len(whole)  # the cut line left out
    first = [float(v) for v in whole[0].split(",")]
    assert imu[0].linear_acceleration.z == pytest.approx(first[2] * 9.80665)
    assert imu[0].angular_velocity.x == pytest.approx(math.radians(first[3]))
    assert imu[0].header.frame_id == "imu_link"
    raw = (folder / "imu_1730.csv.tag").read_bytes()
    _tick_f, time_time, time_sec = struct.unpack_from("<IId", raw, 60)
    last_tick = struct.unpack_from("<I", raw, len(raw) - 8)[0]
    t = np.array([m.t_ns for m in messages if m.topic == "/imu/data_raw"])
    assert t[0] == pytest.approx((time_time + time_sec - 18) * 1e9, abs=1e3)  # no time offset
    assert t[-1] == pytest.approx((time_time + time_sec + last_tick / 1e3 - 18) * 1e9, abs=1e3)
    assert np.all(np.diff(t) > 0)
    mounting = yaml.safe_load((REPO / "config" / "walk.yaml").read_text())[
        "imu_preprocessor"]["ros__parameters"]["mounting_rpy_deg"]
    f = np.mean([[m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z]
                 for m in imu[:100]], axis=0)
    f_base = Rotation.from_euler("ZYX", mounting[::-1], degrees=True).apply(f)
    assert math.degrees(math.atan2(math.hypot(f_base[0], f_base[1]), f_base[2])) < 3.0
