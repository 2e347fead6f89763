"""Reader for the real car trial ``car_drive_0708`` (rtklibexplorer GNSS_IMU, drive_0708).

Files (see ``/work/shared/data/README.md``):

* ``imu_1934.csv``: ``ax,ay,az,gx,gy,gz,t`` at 100 Hz in g, deg/s and ms since IMU power-up,
  in the IMU's own axes.
* ``imu_1934.csv.tag``: RTKLIB time tags that place the log on GPS time.
* ``gnss_1934_sf.pos``: RTKLIB solution of the roof antenna, 4 Hz, RTK fixed almost throughout;
  the fixed epochs are the reference truth.
* ``gnss_1934.ubx.tag``: time tags of a u-blox log whose ``.ubx`` is not in the data set, so no
  raw GNSS observations are available for this drive.

Installation (from the source's configuration): body frame forward-right-down; the IMU axes are
rotated by roll/pitch/yaw (180, 0, 180) deg and then by (0, -6.79, 5.35) deg relative to the body.
The rotations act on IMU vectors in that order, v_frd = C2 C1 v_imu with each C = Rz(yaw)
Ry(pitch) Rx(roll); the tests prove this order and these signs on the data (gravity along body z
when static, no forward acceleration leaking into the lateral axis, the road grade appearing in
the forward axis). The IMU clock needs -0.125 s to line up with GNSS time; the reader keeps this
offset as a separate field instead of applying it.
"""
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ins_gnss_ros.nav.conventions import azimuth_from_yaw, frd_to_flu
from ins_gnss_ros.nav.rotations import dcm_from_euler
from ins_gnss_ros.trial.evaluate import Trajectory
from ins_gnss_ros.trial.rtklib import Q_FIX, PosSolution, read_pos, read_time_tag

#: m/s^2 per g, the unit of the accelerometer output (standard gravity, 3rd CGPM 1901).
STANDARD_GRAVITY = 9.80665

#: Add to the tag-file IMU times to align them with GNSS time, s (source configuration).
IMU_TIME_OFFSET_S = -0.125
#: Geoid height at the site, m: the ``.pos`` files of this source hold u-blox hMSL, not
#: ellipsoidal height (their converter wrote NAV-PVT hMSL); the walk_0827 stream's NAV-PVT gives
#: height - hMSL = -21.387 m there, and both recordings start within 300 m of each other.
SITE_GEOID_SEPARATION_M = -21.387

#: IMU mounting: two successive (roll, pitch, yaw) rotations, deg, of the IMU axes in the FRD body.
IMU_MOUNT_EULER_DEG = ((180.0, 0.0, 180.0), (0.0, -6.79, 5.35))

#: Offsets from the system origin, FRD body frame, m (source configuration).
IMU_OFFSET_FRD = (0.0, 0.0, -0.65)
ANTENNA_OFFSET_FRD = (0.0, -0.05, -0.65)

#: Below this horizontal speed, m/s, the RTK velocity does not define a course.
MIN_COURSE_SPEED = 1.0

_IMU_FIELDS = 7


@dataclass(frozen=True)
class CarDrive:
    """The car trial in project conventions.

    Attributes
    ----------
    imu_time : ndarray, shape (n,)
        IMU sample times, GPS seconds, from the ``.tag`` mapping alone (offset NOT applied).
    imu_time_offset : float
        Add to `imu_time` to align the IMU with GNSS time, s (-0.125).
    accel_flu : ndarray, shape (n, 3)
        Specific force in the body frame FLU, m/s^2.
    gyro_flu : ndarray, shape (n, 3)
        Angular rate in the body frame FLU, rad/s.
    imu_tick_ms : ndarray, shape (n,)
        Raw IMU time stamps, ms since power-up.
    gnss : PosSolution
        Every RTKLIB epoch (antenna position), GPS seconds.
    truth : Trajectory
        The RTK-fixed epochs (Q = 1): antenna position and ENU velocity, no attitude.
    truth_course : ndarray, shape (m,)
        Course over ground of `truth` (azimuth of the velocity, rad, clockwise from north), NaN
        below `MIN_COURSE_SPEED`.
    imu_offset_flu, antenna_offset_flu : ndarray, shape (3,)
        IMU and antenna positions relative to the system origin, body FLU, m.
    """

    imu_time: np.ndarray
    imu_time_offset: float
    accel_flu: np.ndarray
    gyro_flu: np.ndarray
    imu_tick_ms: np.ndarray
    gnss: PosSolution
    truth: Trajectory
    truth_course: np.ndarray
    imu_offset_flu: np.ndarray
    antenna_offset_flu: np.ndarray

    @property
    def imu_time_gnss(self):
        """IMU sample times aligned with GNSS time (offset applied), GPS seconds."""
        return self.imu_time + self.imu_time_offset

    @property
    def antenna_lever_arm_flu(self):
        """Antenna position relative to the IMU, body FLU, m."""
        return self.antenna_offset_flu - self.imu_offset_flu


def read_imu_csv(path):
    """Read the IMU log, skipping a non-numeric header line and an incomplete last line.

    Returns
    -------
    values : ndarray, shape (n, 6)
        ax, ay, az (g) and gx, gy, gz (deg/s), IMU axes.
    tick_ms : ndarray, shape (n,)
        Time stamps, ms since IMU power-up.

    Raises
    ------
    ValueError
        For a malformed line other than the header and the last line, naming the line.
    """
    path = Path(path)
    lines = path.read_text(encoding="ascii", errors="replace").splitlines(keepends=True)
    start = 0 if lines and _is_numeric_row(lines[0]) else 1
    # A log cut off while writing ends without a newline or with fewer fields.
    if lines and (not lines[-1].endswith("\n") or not _is_numeric_row(lines[-1])):
        lines = lines[:-1]
    rows = np.empty((len(lines) - start, _IMU_FIELDS))
    for number, line in enumerate(lines[start:], start=start + 1):
        try:
            fields = [float(value) for value in line.split(",")]
            if len(fields) != _IMU_FIELDS:
                raise ValueError(f"{len(fields)} fields, expected {_IMU_FIELDS}")
        except ValueError as error:
            raise ValueError(f"{path}:{number}: {error}: {line.strip()!r}") from None
        rows[number - start - 1] = fields
    return rows[:, :6], rows[:, 6]


def imu_times(tick_ms, tag):
    """GPS times of IMU samples: `tick_ms` mapped linearly onto the tag file's start and end.

    The first sample is placed at the log start (``time_time + time_sec``) and the last at the
    start plus the last tag tick (README of the data set); between them the IMU clock is
    stretched linearly, which absorbs its rate error against GPS time.
    """
    tick_ms = np.asarray(tick_ms, float)
    fraction = (tick_ms - tick_ms[0]) / (tick_ms[-1] - tick_ms[0])
    return tag.start_time + fraction * (tag.end_time - tag.start_time)


def imu_to_body_dcm():
    """C_flu,imu: rotates IMU-axis vectors into the FLU body frame."""
    (r1, p1, y1), (r2, p2, y2) = np.radians(IMU_MOUNT_EULER_DEG)
    c_frd_imu = dcm_from_euler(r2, p2, y2) @ dcm_from_euler(r1, p1, y1)
    return frd_to_flu(c_frd_imu.T).T  # flip the rows: F C, with F = diag(1, -1, -1)


def course_over_ground(vel_enu, min_speed=MIN_COURSE_SPEED):
    """Azimuth (rad, clockwise from north, [0, 2 pi)) of ENU velocity; NaN below `min_speed`."""
    vel_enu = np.asarray(vel_enu, float)
    course = azimuth_from_yaw(np.arctan2(vel_enu[:, 1], vel_enu[:, 0]))
    return np.where(np.hypot(vel_enu[:, 0], vel_enu[:, 1]) >= min_speed, course, np.nan)


def load_car_drive(folder):
    """Load the car trial from its folder (``.../car_drive_0708``).

    Returns
    -------
    CarDrive
    """
    folder = Path(folder)
    values, tick_ms = read_imu_csv(folder / "imu_1934.csv")
    tag = read_time_tag(folder / "imu_1934.csv.tag")
    c_body_imu = imu_to_body_dcm()
    gnss = read_pos(folder / "gnss_1934_sf.pos", SITE_GEOID_SEPARATION_M)
    fixed = gnss.select(gnss.quality == Q_FIX)
    truth = Trajectory(time=fixed.time, lat=fixed.lat, lon=fixed.lon, height=fixed.height,
                       vel_enu=fixed.vel_enu, pos_cov_enu=fixed.pos_cov_enu,
                       vel_cov_enu=fixed.vel_cov_enu)
    return CarDrive(
        imu_time=imu_times(tick_ms, tag),
        imu_time_offset=IMU_TIME_OFFSET_S,
        accel_flu=STANDARD_GRAVITY * values[:, :3] @ c_body_imu.T,
        gyro_flu=np.radians(values[:, 3:]) @ c_body_imu.T,
        imu_tick_ms=tick_ms,
        gnss=gnss,
        truth=truth,
        truth_course=course_over_ground(fixed.vel_enu),
        imu_offset_flu=frd_to_flu(IMU_OFFSET_FRD),
        antenna_offset_flu=frd_to_flu(ANTENNA_OFFSET_FRD),
    )


def _is_numeric_row(line):
    fields = line.strip().split(",")
    if len(fields) != _IMU_FIELDS:
        return False
    try:
        [float(value) for value in fields]
    except ValueError:
        return False
    return True
