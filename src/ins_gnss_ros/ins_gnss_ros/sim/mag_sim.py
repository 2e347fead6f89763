"""Three-axis magnetometer on a vehicle.

Measurement model (the usual compass-deviation model, e.g. Gebre-Egziabher et al., "Calibration
of strapdown magnetometers in magnetic field domain", J. Aerosp. Eng. 2006, eq. 1; seed 004
§2.9 for the sensor offsets ΔF):

    m^b = (I + S) [ (I + W) B_ext^b + B_hard^b ] + ΔF + η,    B_ext^b = C_bn (B_earth^n + B_dip^n)

* B_earth^n: the Earth's field, given by the caller (WMM/IGRF lookup lives elsewhere);
* B_dip^n: optional disturbances by steel masses, each a magnetic dipole fixed on the ground,
  B = μ0/(4π r³) (3 (m·r̂) r̂ − m), which rises and falls as the vehicle passes;
* W: soft iron, the field induced in the vehicle's steel by the external field;
* B_hard^b: hard iron, the vehicle's (ship's) permanent field at the sensor, fixed in the body;
* S: the sensor's own scale-factor and non-orthogonality errors;
* ΔF: the sensor's zero offsets; η: white noise.

Units: tesla (sensor_msgs/MagneticField). Body frame FLU.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ins_gnss_ros.nav import earth
from ins_gnss_ros.nav.conventions import ned_to_enu
from ins_gnss_ros.nav.rotations import quat_to_dcm
from ins_gnss_ros.sim.trajectory import Trajectory

MU0_4PI = 1e-7  # μ0 / 4π, T·m/A


@dataclass(frozen=True)
class Dipole:
    """A steel mass on the ground modelled as a magnetic dipole.

    Attributes
    ----------
    lat, lon, h : float
        Location, rad, rad, m.
    moment_enu : tuple of 3 float
        Dipole moment in ENU, A·m² (a car ≈ 100–300 A·m²; a large ship ≈ 1e5–1e6 A·m²).
    """

    lat: float
    lon: float
    h: float
    moment_enu: tuple

    def field_enu(self, lat, lon, h):
        """Field of the dipole at geodetic point(s), ENU at the dipole, T, shape (n, 3)."""
        r = earth.ecef_to_enu(earth.geodetic_to_ecef(lat, lon, h), self.lat, self.lon, self.h)
        dist = np.linalg.norm(r, axis=-1, keepdims=True)
        rhat = r / dist
        m = np.asarray(self.moment_enu, float)
        return MU0_4PI * (3.0 * (rhat @ m)[:, None] * rhat - m) / dist ** 3


@dataclass(frozen=True)
class MagErrors:
    """Magnetometer and vehicle-field errors (all zero by default).

    Attributes
    ----------
    hard_iron_b : ndarray, shape (3,)
        Vehicle's (ship's) permanent field at the sensor, body, T.
    soft_iron : ndarray, shape (3, 3)
        Induced-field matrix W (dimensionless).
    scale_misalignment : ndarray, shape (3, 3)
        Sensor scale-factor (diagonal) and non-orthogonality (off-diagonal) errors S.
    offset_b : ndarray, shape (3,)
        Sensor zero offsets ΔF, T.
    noise_std : float
        White noise per sample and axis, T.
    """

    hard_iron_b: np.ndarray = field(default_factory=lambda: np.zeros(3))
    soft_iron: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    scale_misalignment: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    offset_b: np.ndarray = field(default_factory=lambda: np.zeros(3))
    noise_std: float = 0.0

    @classmethod
    def uncalibrated_vehicle(cls, rng: np.random.Generator, noise_std: float) -> "MagErrors":
        """Errors of a MEMS magnetometer in a car nobody calibrated, drawn from ``rng``.

        Magnitudes as reported for automotive and robot installations (Gebre-Egziabher et
        al. 2006, §"Error sources"; Caruso, "Applications of magnetic sensors for low cost
        compass systems", IEEE PLANS 2000): a hard iron of about 10 uT per axis (of the order
        of the horizontal field at high latitudes), soft iron of a few per cent (symmetric:
        the induced field of linear steel), scale errors of 1 % and non-orthogonality of
        0.5 % (the sensor's own, not symmetric) and zero offsets of 1 uT.
        """
        w = rng.normal(0.0, 0.02, (3, 3))
        w = 0.5 * (w + w.T) + np.diag(rng.normal(0.0, 0.03, 3))
        s = np.diag(rng.normal(0.0, 0.01, 3)) + rng.normal(0.0, 0.005, (3, 3)) * (1 - np.eye(3))
        return cls(hard_iron_b=rng.normal(0.0, 10e-6, 3), soft_iron=w, scale_misalignment=s,
                   offset_b=rng.normal(0.0, 1e-6, 3), noise_std=noise_std)


@dataclass
class MagMeasurements:
    """Simulated magnetometer samples.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Sample time, s.
    field_b : ndarray, shape (n, 3)
        Measured field, body FLU, T.
    external_b : ndarray, shape (n, 3)
        True external field (Earth + disturbances) in body axes, T.
    disturbance_n : ndarray, shape (n, 3)
        True dipole disturbance in ENU, T.
    """

    t: np.ndarray
    field_b: np.ndarray
    external_b: np.ndarray
    disturbance_n: np.ndarray


def simulate_magnetometer(traj: Trajectory, earth_field, errors: MagErrors = MagErrors(),
                          rate: float = 50.0, seed: int = 0, dipoles=(),
                          frame: str = "ENU") -> MagMeasurements:
    """Magnetometer output along a trajectory.

    Parameters
    ----------
    traj : Trajectory
        Truth; its rate must be an integer multiple of ``rate``.
    earth_field : array_like, shape (3,) or (len(traj), 3)
        Earth's field in the navigation frame, T (constant, or per trajectory sample).
    errors : MagErrors
    rate : float
        Sample rate, Hz.
    seed : int
        Seed of the noise.
    dipoles : sequence of Dipole
        Steel masses on the ground.
    frame : {"ENU", "NED"}
        Frame in which ``earth_field`` is given.

    Returns
    -------
    MagMeasurements
    """
    idx = np.arange(0, len(traj), traj.decimation(rate))
    b_n = np.broadcast_to(np.asarray(earth_field, float), (len(traj), 3))[idx]
    if frame.upper() == "NED":
        b_n = ned_to_enu(b_n)
    elif frame.upper() != "ENU":
        raise ValueError(f"unknown frame {frame!r}")
    dist = np.zeros((len(idx), 3))
    for d in dipoles:
        dist += d.field_enu(traj.lat[idx], traj.lon[idx], traj.h[idx])
    c_nb = quat_to_dcm(traj.q_nb[idx])
    ext_b = np.einsum("kji,kj->ki", c_nb, b_n + dist)
    eye = np.eye(3)
    m = (ext_b @ (eye + errors.soft_iron).T + errors.hard_iron_b) \
        @ (eye + errors.scale_misalignment).T
    noise = errors.noise_std * np.random.default_rng(seed).standard_normal(m.shape)
    return MagMeasurements(traj.t[idx], m + errors.offset_b + noise, ext_b, dist)
