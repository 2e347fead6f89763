"""Reader for the simulated vessel in waves (smsfusion test data ``ains_ahrs_imu.parquet``).

The source (an OrcaFlex simulation, 10.24 Hz) is in a local NED frame with an FRD body:

* ``X, Y, Z`` position (m) and ``VX, VY, VZ`` velocity (m/s), NED;
* ``Alpha, Beta, Gamma`` roll, pitch, yaw (deg) with C_ned,frd = Rz(yaw) Ry(pitch) Rx(roll);
* ``Ax..Az`` specific force (m/s^2) and ``Gx..Gz`` angular rate (deg/s), FRD, true and
  ``*_meas`` with IMU noise;
* ``X_meas, Y_meas, Z_meas`` GNSS position with 5 cm noise and ``Gamma_meas`` compass heading
  (deg) with 0.1 deg noise.

The local NED frame has no geodetic anchor, so this reader places its origin at a datum, by
default 60 deg N 5 deg E on the sea surface (h = 0), off the Norwegian west coast where the
source's operator works: any datum serves, since the simulation ignores Earth rotation and
curvature (the tests check that the truth is self-consistent without them). Over the few metres
the vessel moves, the ENU tangent plane at the datum and the ellipsoid differ by well under a mm.
"""
from dataclasses import dataclass

import numpy as np
import pandas as pd

from ins_gnss_ros.nav.conventions import frd_to_flu, ned_to_enu, quat_ned_frd_to_enu_flu, wrap_2pi
from ins_gnss_ros.nav.earth import ecef_to_geodetic, enu_to_ecef
from ins_gnss_ros.nav.rotations import quat_from_euler
from ins_gnss_ros.trial.evaluate import Trajectory

#: Default geodetic origin (lat rad, lon rad, h m) of the source's local NED frame.
DEFAULT_DATUM = (np.radians(60.0), np.radians(5.0), 0.0)


@dataclass(frozen=True)
class VesselTrial:
    """The vessel trial in project conventions (ENU navigation frame, FLU body, SI units).

    Attributes
    ----------
    time : ndarray, shape (n,)
        Simulation time, s (not GPS time).
    truth : Trajectory
        True position (geodetic via `datum`), ENU velocity and attitude q_nb.
    accel_flu_true, gyro_flu_true : ndarray, shape (n, 3)
        True specific force (m/s^2) and angular rate (rad/s), body FLU.
    accel_flu, gyro_flu : ndarray, shape (n, 3)
        Measured (noisy) specific force and angular rate, body FLU.
    gnss : Trajectory
        GNSS position fixes (5 cm white noise), one per sample, without velocity or attitude.
    compass_azimuth : ndarray, shape (n,)
        Compass heading, rad, clockwise from north (true north: the frame has no declination).
    datum : tuple of float
        (lat rad, lon rad, h m) of the local frame's origin.
    """

    time: np.ndarray
    truth: Trajectory
    accel_flu_true: np.ndarray
    gyro_flu_true: np.ndarray
    accel_flu: np.ndarray
    gyro_flu: np.ndarray
    gnss: Trajectory
    compass_azimuth: np.ndarray
    datum: tuple


def local_ned_to_geodetic(ned, datum=DEFAULT_DATUM):
    """Geodetic (lat, lon, h) of positions `ned` (n, 3), m, in a local NED frame at `datum`."""
    lat, lon, height = ecef_to_geodetic(enu_to_ecef(ned_to_enu(ned), *datum))
    return lat, lon, height


def load_vessel(path, datum=DEFAULT_DATUM):
    """Load ``ains_ahrs_imu.parquet`` and convert it to project conventions.

    Parameters
    ----------
    path : str or Path
        The parquet file.
    datum : tuple of float
        Geodetic origin (lat rad, lon rad, h m) for the local NED positions.

    Returns
    -------
    VesselTrial
    """
    frame = pd.read_parquet(path)
    time = frame.index.to_numpy(dtype=float)

    def columns(*names):
        return frame[list(names)].to_numpy(dtype=float)

    lat, lon, height = local_ned_to_geodetic(columns("X", "Y", "Z"), datum)
    roll, pitch, yaw = np.radians(columns("Alpha", "Beta", "Gamma")).T
    truth = Trajectory(time=time, lat=lat, lon=lon, height=height,
                       vel_enu=ned_to_enu(columns("VX", "VY", "VZ")),
                       q_nb=quat_ned_frd_to_enu_flu(quat_from_euler(roll, pitch, yaw)))
    gnss_lat, gnss_lon, gnss_height = local_ned_to_geodetic(
        columns("X_meas", "Y_meas", "Z_meas"), datum)
    return VesselTrial(
        time=time,
        truth=truth,
        accel_flu_true=frd_to_flu(columns("Ax", "Ay", "Az")),
        gyro_flu_true=frd_to_flu(np.radians(columns("Gx", "Gy", "Gz"))),
        accel_flu=frd_to_flu(columns("Ax_meas", "Ay_meas", "Az_meas")),
        gyro_flu=frd_to_flu(np.radians(columns("Gx_meas", "Gy_meas", "Gz_meas"))),
        gnss=Trajectory(time=time, lat=gnss_lat, lon=gnss_lon, height=gnss_height),
        # The NED yaw is already an azimuth (clockwise from north).
        compass_azimuth=wrap_2pi(np.radians(frame["Gamma_meas"].to_numpy(dtype=float))),
        datum=tuple(datum),
    )
