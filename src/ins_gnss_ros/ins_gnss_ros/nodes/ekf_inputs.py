"""The ekf's aiding messages as the filter's front end takes them, for the node and the offline
replay alike.

:class:`EkfInputs` turns each aiding message (``gnss/fix``, ``gnss/vel``, the heading topics,
``gnss/phase_dd``, ``log/speed``, ``wheel/odom`` and, coupled tightly, ``gnss/observations`` with
``gnss/ephemeris``) into the call of :class:`ins_gnss_ros.nav.aiding.Aiding` that judges it.
The ``ekf`` node subscribes to :meth:`EkfInputs.handlers` and ``trial replay --offline`` feeds
the bag's messages to the same handlers, so both read a profile's inputs the same way: the same
topics, the same covariance conventions, the same single-point alignment. No rclpy here: the
handlers take message objects.
"""

from __future__ import annotations

from functools import partial
from typing import Callable

import numpy as np
from geometry_msgs.msg import TwistWithCovarianceStamped
from ins_gnss_msgs.msg import GnssEphemeris, GnssObservations, Heading, PhaseDoubleDifferences
from nav_msgs.msg import Odometry
from sensor_msgs.msg import NavSatFix, NavSatStatus

from ..gnss.constants import GALILEO, GPS, UBX_GNSS_ID
from ..gnss.ranges import RangeConfig, ephemeris_valid, satellite_ranges
from ..gnss.spp import DEFAULT_SIGNALS, SppConfig, solve_position, solve_velocity
from ..io import stamp_to_sec
from ..nav.aiding import Aiding
from ..nav.filter_config import HEADING_INPUTS
from .convert import heading_of, vec
from .gnss_messages import kepler_from_msg, raw_epoch_from_msg

#: A handler takes a message and says whether the filter took something from it.
Handler = Callable[[object], bool]


class EkfInputs:
    """Aiding messages -> :class:`Aiding`, configured by the ``ekf`` parameters ``p``;
    ``count(text, log=True)`` reports a refused message (the node's /diagnostics counter)."""

    def __init__(self, aiding: Aiding, p: dict, count: Callable[..., None]):
        self.aiding, self.p, self.count = aiding, p, count
        self.raw = RawGnss(aiding, p, count) if p["coupling"] != "loose" else None
        # NavSatStatus (status, service) of the last gnss/fix the filter took: nav/fix
        # reports the augmentation it navigates on.
        self.fix_input = (NavSatStatus.STATUS_FIX, 0)

    def handlers(self) -> dict[str, tuple[type, Handler]]:
        """topic (relative) -> (message type, handler) of every input the profile uses."""
        p, out = self.p, {}
        # With a single-point alignment the receiver's fix and velocity are no input.
        if self.raw is None or self.raw.spp is None:
            out["gnss/fix"] = (NavSatFix, self.fix)
            out["gnss/vel"] = (TwistWithCovarianceStamped, self.velocity)
        if self.raw is not None:
            out["gnss/observations"] = (GnssObservations, self.raw.observations)
            out["gnss/ephemeris"] = (GnssEphemeris, self.raw.ephemeris)
        for topic, use in HEADING_INPUTS.items():
            if p[use]:
                out[topic] = (Heading, partial(self.heading, topic))
        if p["use_phase_dd"]:
            out["gnss/phase_dd"] = (PhaseDoubleDifferences, self.phase_dd)
        if p["use_speed_log"]:
            out["log/speed"] = (TwistWithCovarianceStamped, self.speed_log)
        if p["use_wheel_odometry"]:
            out["wheel/odom"] = (Odometry, self.wheel)
        return out

    def fix(self, msg: NavSatFix) -> bool:
        taken = self.aiding.fix(stamp_to_sec(msg.header.stamp), msg.latitude, msg.longitude,
                                msg.altitude, np.reshape(msg.position_covariance, (3, 3)),
                                msg.status.status,
                                msg.position_covariance_type != NavSatFix.COVARIANCE_TYPE_UNKNOWN)
        if taken:
            self.fix_input = (msg.status.status, msg.status.service)
        return taken

    def velocity(self, msg: TwistWithCovarianceStamped) -> bool:
        return self.aiding.velocity(stamp_to_sec(msg.header.stamp), vec(msg.twist.twist.linear),
                                    np.reshape(msg.twist.covariance, (6, 6))[:3, :3])

    def heading(self, topic: str, msg: Heading) -> bool:
        reading = heading_of(msg)
        return reading is not None and self.aiding.heading(*reading, source=topic)

    def phase_dd(self, msg: PhaseDoubleDifferences) -> bool:
        """The rows whose ambiguity is FIXED (arrays of unequal length: none)."""
        n = len(msg.value)
        cov = np.asarray(msg.covariance, float)
        rows = [j for j, status in enumerate(msg.ambiguity_status)
                if status == PhaseDoubleDifferences.AMBIGUITY_FIXED]
        if not (len(msg.baseline) == len(msg.line_of_sight_difference) ==
                len(msg.ambiguity_status) == n and cov.size == n * n):
            rows = []
        return self.aiding.phase_differences(
            stamp_to_sec(msg.header.stamp),
            np.array([vec(msg.baseline[j]) for j in rows]).reshape(-1, 3),
            np.array([vec(msg.line_of_sight_difference[j]) for j in rows]).reshape(-1, 3),
            np.asarray(msg.value, float)[rows], cov.reshape(n, n)[np.ix_(rows, rows)] if rows
            else np.zeros((0, 0)))

    def speed_log(self, msg: TwistWithCovarianceStamped) -> bool:
        return self.aiding.speed_log(stamp_to_sec(msg.header.stamp), msg.twist.twist.linear.x,
                                     msg.twist.covariance[0])

    def wheel(self, msg: Odometry) -> bool:
        return self.aiding.wheel_odometry(stamp_to_sec(msg.header.stamp),
                                          vec(msg.twist.twist.linear),
                                          np.diag(np.reshape(msg.twist.covariance, (6, 6)))[:3])


class RawGnss:
    """``gnss/ephemeris`` and ``gnss/observations`` for tight coupling: the pseudoranges and
    Dopplers of each epoch with the broadcast orbits (gnss/ranges.py), once the filter may use
    ranges; before that, with ``tight.align_on_observations``, the epoch's single-point fix and
    Doppler velocity (gnss/spp.py) stand in for ``gnss/fix`` and ``gnss/vel``."""

    def __init__(self, aiding: Aiding, p: dict, count: Callable[..., None]):
        self.aiding, self.count = aiding, count
        self.config = RangeConfig(
            signals={sys_: "1C" for sys_, on in ((GPS, p["tight.gps"]), (GALILEO, p["tight.galileo"]))
                     if on},
            elevation_mask=np.radians(p["tight.elevation_mask_deg"]),
            code_sigma=tuple(p["tight.code_sigma_m"]),
            doppler_sigma=tuple(p["tight.doppler_sigma_hz"]),
            klobuchar=(tuple(p["tight.klobuchar"][:4]), tuple(p["tight.klobuchar"][4:]))
            if any(p["tight.klobuchar"]) else None)
        self.spp = SppConfig(elevation_mask=self.config.elevation_mask, iono_free=False,
                             klobuchar=self.config.klobuchar,
                             sigma0=float(np.hypot(*self.config.code_sigma)),
                             signals={s: DEFAULT_SIGNALS[s] for s in self.config.signals}) \
            if p["tight.align_on_observations"] else None
        self.spp_x0 = None  # the last single-point position, ECEF m: the next one starts there
        self.ephemeris_msgs: dict[str, GnssEphemeris] = {}

    def ephemeris(self, msg: GnssEphemeris) -> bool:
        system = UBX_GNSS_ID.get(int(msg.system))
        if system in self.config.signals:
            self.ephemeris_msgs[f"{system}{int(msg.prn):02d}"] = msg
        return False

    def observations(self, msg: GnssObservations) -> bool:
        parsed = raw_epoch_from_msg(msg, set(self.config.signals))
        if parsed is None:
            self.count("gnss/observations with arrays of unequal length rejected")
            return False
        raw = parsed[0]
        ephemerides = {}
        for o in raw.obs:
            sat = f"{o.system}{o.prn:02d}"
            if sat in self.ephemeris_msgs and sat not in ephemerides:
                eph = kepler_from_msg(self.ephemeris_msgs[sat], raw.t_gps)
                if ephemeris_valid(eph, raw.t_gps):
                    ephemerides[sat] = eph
        nav, t = self.aiding.navigator, stamp_to_sec(msg.header.stamp)
        if not self.aiding.choose_ranges(len(ephemerides)):
            return self.spp is not None and self.single_point(raw, ephemerides, t)
        return self.aiding.ranges(satellite_ranges(raw, ephemerides, t, nav.state_at(t),
                                                   nav.lever_arm_b, self.config))

    def single_point(self, raw, ephemerides, t: float) -> bool:
        sol = solve_position(raw, ephemerides, self.spp, self.spp_x0)
        if sol is None or not sol.valid:
            self.count("observation epoch without a single-point solution", log=False)
            return False
        self.spp_x0 = sol.xyz
        vel = solve_velocity(raw, ephemerides, sol, self.spp,
                             float(np.hypot(*self.config.doppler_sigma)))
        fixed = self.aiding.fix(t, np.degrees(sol.lat), np.degrees(sol.lon), sol.h,
                                sol.covariance_enu, NavSatStatus.STATUS_FIX, True)
        return bool(vel is not None and self.aiding.velocity(t, vel[0], vel[2])) or fixed
