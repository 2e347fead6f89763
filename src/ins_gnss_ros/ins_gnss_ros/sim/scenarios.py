"""Named simulation scenarios after the laboratory works of seed 004.

* ``car`` — Lab 1 (seed 004 §4, car trials of the MEMS tightly-coupled prototype): town
  driving in St Petersburg with straights, 90° turns and stops at lights, then circles and
  figure-eights "of minimal radius at the maximum feasible speed" (cyclic lateral loads), then
  town driving again; with a satellite-shading schedule that limits the constellation to 6, 4,
  3 and 2 satellites in turn (the lab's constellation ablation, seed 004 §1.4 and §2.13).
* ``sea`` — Lab 2 (R/V "Azimut", Lake Ladoga): a vessel at 6–10 m/s changing course every one
  to two minutes, in a short-fetch lake sea (see :mod:`ins_gnss_ros.sim.waves`), with a water
  current for the speed log.
* ``robot`` — a wheeled ground robot (issue 15's): after a standstill, straight runs of 15-30 s
  at 0.5-1.5 m/s joined by 90° turns on the spot's scale (3 m radius), the slow motion whose
  course the fixes of a single-point receiver show only over tens of seconds.
* ``aircraft`` — seed 003's flight trials of the SAR micronavigation system: an aircraft at
  100-200 m/s flying straight survey legs (the synthetic apertures) with the small heading and
  pitch corrections of manual or autopilot flight (the trajectory instabilities the system
  measures), joined by banked racetrack turns; the system starts in flight.

All are seeded: the same seed and duration give the identical trajectory.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ins_gnss_ros.sim import waves
from ins_gnss_ros.sim.trajectory import CarMotion, Route, ShipMotion, Trajectory, generate

#: Lab 1 start: St Petersburg; ellipsoidal height = ~5 m above sea level + ~17 m geoid.
CAR_START = (np.deg2rad(59.9), np.deg2rad(30.3), 22.0)
#: Lab 2 start: Lake Ladoga (surface ~5 m above sea level + ~17 m geoid).
SEA_START = (np.deg2rad(60.8), np.deg2rad(31.5), 22.0)

#: Seed 003's flight start: over the Leningrad region, 3 km ellipsoidal height.
AIRCRAFT_START = (np.deg2rad(59.8), np.deg2rad(30.3), 3000.0)
#: Standard gravity, m/s^2: the bank of a coordinated turn is atan(lateral acceleration / g).
_G = 9.80665

#: Peak lateral acceleration of the car's circles and figure-eights, m/s² (≈0.6 g: a dry-road
#: handling limit of a passenger car, "maximum feasible speed" in seed 004 Lab 1).
CAR_TEST_LATERAL_ACCEL = 6.0


@dataclass(frozen=True)
class ShadingWindow:
    """A time window in which the GNSS simulator keeps at most ``max_satellites`` in view.

    Attributes
    ----------
    t_start, t_end : float
        Window, s from the start of the trajectory.
    max_satellites : int
    """

    t_start: float
    t_end: float
    max_satellites: int


@dataclass
class Scenario:
    """A simulated trial: truth trajectory plus the environment the sensor simulators need.

    Attributes
    ----------
    name : str
    seed : int
    trajectory : Trajectory
    shading : list of ShadingWindow
        Satellite-count limits for the GNSS simulator (empty: open sky throughout).
    water_current_enu : ndarray, shape (3,)
        Mean water current (velocity of the water over ground) in ENU, m/s; zero on land.
    max_lateral_accel : float
        Largest commanded centripetal acceleration of the route, m/s².
    """

    name: str
    seed: int
    trajectory: Trajectory
    shading: list = field(default_factory=list)
    water_current_enu: np.ndarray = field(default_factory=lambda: np.zeros(3))
    max_lateral_accel: float = 0.0


def shading_schedule(duration: float, counts=(6, 4, 3, 2), first: float = 120.0,
                     length: float = 45.0, gap: float = 30.0) -> list:
    """Shading windows of ``length`` s separated by ``gap`` s of open sky, cycling through
    ``counts`` satellites, from ``first`` s until ``duration``.

    Returns
    -------
    list of ShadingWindow
    """
    out, t, k = [], float(first), 0
    while t < duration:
        out.append(ShadingWindow(t, min(t + length, duration), int(counts[k % len(counts)])))
        t += length + gap
        k += 1
    return out


def _town_block(route: Route, rng: np.random.Generator) -> None:
    """One city block: accelerate, cruise (maybe over a grade), then a 90° turn or a stop."""
    route.change_speed(rng.uniform(9.0, 14.0), rng.uniform(1.5, 2.5))
    if rng.uniform() < 0.4:
        route.set_pitch(rng.uniform(-0.04, 0.04), 4.0)
    route.hold(rng.uniform(8.0, 18.0))
    if rng.uniform() < 0.3:
        route.stop(rng.uniform(5.0, 12.0), decel=rng.uniform(1.5, 3.0))
        route.change_speed(rng.uniform(8.0, 12.0), 2.0).hold(3.0)
    route.change_speed(rng.uniform(6.0, 8.0), 2.0)
    route.turn(np.pi / 2 * rng.choice([-1.0, 1.0]), radius=rng.uniform(12.0, 25.0))
    route.set_pitch(0.0, 3.0)


def _test_area(route: Route) -> None:
    """Cyclic lateral loads: a left and a right circle, then two figure-eights."""
    route.change_speed(9.0, 2.0).hold(3.0)
    route.circle(lateral_accel=CAR_TEST_LATERAL_ACCEL, direction=1)
    route.hold(3.0)
    route.circle(lateral_accel=CAR_TEST_LATERAL_ACCEL, direction=-1)
    route.hold(3.0)
    route.figure_eight(lateral_accel=CAR_TEST_LATERAL_ACCEL, laps=2)
    route.hold(3.0)


#: Speed of the car scenario's rolling start, m/s.
ROLLING_START_SPEED = 10.0


def _start_pitch(grade: float) -> float:
    """Pitch (ROS: positive nose down) of a road of this grade (rise over run), rad."""
    return -float(np.arctan(grade))


def car(duration: float = 600.0, seed: int = 0, rate: float = 200.0, static: float = 30.0,
        start=CAR_START, oversample: int = 4, start_grade: float = 0.0) -> Scenario:
    """Seed 004 Lab 1 car trial: town driving, circles and figure-eights, stops, shading.

    Parameters
    ----------
    duration : float
        Length, s.
    seed : int
    rate : float
        IMU rate, Hz.
    static : float
        Initial standstill for alignment, s; 0: a rolling start (at ROLLING_START_SPEED from the
        first sample, as a recording begun on the move).
    start : (lat, lon, h)
        Start position (rad, rad, m).
    oversample : int
        See :func:`ins_gnss_ros.sim.trajectory.generate`.
    start_grade : float
        Grade of the road at the start, rise over run (0.08: 8 % uphill), held until the
        drive's first change of grade.

    Returns
    -------
    Scenario
    """
    rng = np.random.default_rng(seed)
    route = Route(yaw0=rng.uniform(-np.pi, np.pi),
                  speed0=0.0 if static > 0 else ROLLING_START_SPEED,
                  pitch0=_start_pitch(start_grade))
    route.hold(static)
    for _ in range(3):
        _town_block(route, rng)
    _test_area(route)
    while route.t < duration:
        _town_block(route, rng)
    traj = generate(CarMotion(route), *start, duration, rate, oversample)
    return Scenario("car", seed, traj, shading_schedule(duration),
                    max_lateral_accel=route.max_lateral_accel)


def robot(duration: float = 600.0, seed: int = 0, rate: float = 200.0, static: float = 30.0,
          start=CAR_START, oversample: int = 4, start_grade: float = 0.0) -> Scenario:
    """A wheeled ground robot: a standstill of ``static`` s (0: starting at a run's speed),
    then straight runs of 15-30 s, each at 0.5-1.5 m/s (reached at 0.5 m/s^2), joined by
    left or right turns of 90 deg on a 3 m radius (the start's grade held throughout).
    Parameters as :func:`car`'s."""
    rng = np.random.default_rng(seed)
    route = Route(yaw0=rng.uniform(-np.pi, np.pi), speed0=0.0 if static > 0 else 1.0,
                  pitch0=_start_pitch(start_grade))
    route.hold(static)
    while route.t < duration:
        route.change_speed(rng.uniform(0.5, 1.5), 0.5).hold(rng.uniform(15.0, 30.0))
        route.turn(np.pi / 2 * rng.choice([-1.0, 1.0]), radius=3.0)
    traj = generate(CarMotion(route), *start, duration, rate, oversample)
    return Scenario("robot", seed, traj, max_lateral_accel=route.max_lateral_accel)


def sea(duration: float = 600.0, seed: int = 0, rate: float = 200.0,
        sea_state: waves.SeaState = waves.SeaState(),
        hull: waves.HullResponse = waves.HullResponse(), start=SEA_START,
        oversample: int = 4) -> Scenario:
    """Seed 004 Lab 2 sea trial: vessel at 6–10 m/s with course changes, in waves.

    Parameters
    ----------
    duration, seed, rate, start, oversample : as in :func:`car`
    sea_state : SeaState
    hull : HullResponse

    Returns
    -------
    Scenario
    """
    rng = np.random.default_rng(seed)
    route = Route(yaw0=rng.uniform(-np.pi, np.pi), speed0=rng.uniform(6.0, 10.0), ramp=10.0)
    while route.t < duration:
        route.hold(rng.uniform(40.0, 90.0))
        route.turn(np.deg2rad(rng.uniform(20.0, 90.0)) * rng.choice([-1.0, 1.0]),
                   radius=rng.uniform(300.0, 600.0))
        route.change_speed(rng.uniform(6.0, 10.0), 0.1)
    motion = ShipMotion(route, waves.wave_motion(sea_state, hull, rng))
    traj = generate(motion, *start, duration, rate, oversample)
    current_dir = rng.uniform(0.0, 2.0 * np.pi)
    current = rng.uniform(0.05, 0.3) * np.array([np.cos(current_dir), np.sin(current_dir), 0.0])
    return Scenario("sea", seed, traj, water_current_enu=current,
                    max_lateral_accel=route.max_lateral_accel)


def aircraft(duration: float = 600.0, seed: int = 0, rate: float = 200.0,
             start=AIRCRAFT_START, oversample: int = 4) -> Scenario:
    """Seed 003 SAR flight: survey legs at 100-200 m/s with trajectory instabilities, turns.

    Legs of 60-120 s, each at up to 20 m/s from the last one's speed (within 100-200 m/s); every 3-8 s the heading changes by
    0.1-0.5 deg over 4 s and the pitch by up to 0.3 deg (a few decimetres of deviation from the straight
    line over an aperture, what the SAR's motion compensation must know to millimetres). Legs
    are joined by 180 deg turns at a 25 deg bank. The motion is :class:`CarMotion`'s (velocity
    along the body x axis: coordinated flight without wind) with the roll of a coordinated
    turn, -v r / g (small-angle form; left turns bank left, negative ROS roll).

    Parameters
    ----------
    duration, seed, rate, start, oversample : as in :func:`car`

    Returns
    -------
    Scenario
    """
    rng = np.random.default_rng(seed)
    route = Route(yaw0=rng.uniform(-np.pi, np.pi), speed0=rng.uniform(100.0, 200.0), ramp=4.0)
    while route.t < duration:
        route.change_speed(np.clip(route.current_speed + rng.uniform(-20.0, 20.0), 100.0, 200.0),
                           1.0)
        leg_end = route.t + rng.uniform(60.0, 120.0)
        while route.t < leg_end:
            route.set_pitch(np.deg2rad(rng.uniform(-0.3, 0.3)), 2.0)
            # Each correction takes 4 s (its yaw-rate ramps): a shorter one of a small angle
            # would step the coordinated-turn roll.
            angle = np.deg2rad(rng.uniform(0.1, 0.5)) * rng.choice([-1.0, 1.0])
            route.turn(angle, radius=route.current_speed * 4.0 / abs(angle))
            route.hold(rng.uniform(3.0, 8.0))
        route.turn(np.pi * rng.choice([-1.0, 1.0]), lateral_accel=_G * np.tan(np.deg2rad(25.0)))
    traj = generate(CarMotion(route, roll_gain=-1.0 / _G), *start, duration, rate, oversample)
    return Scenario("aircraft", seed, traj, max_lateral_accel=route.max_lateral_accel)


#: Scenario factories by name, for ``trial simulate --scenario NAME``.
SCENARIOS = {"car": car, "robot": robot, "sea": sea, "aircraft": aircraft}
