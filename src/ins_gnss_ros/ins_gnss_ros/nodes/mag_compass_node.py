"""``mag_compass`` node: calibrated magnetometer + roll/pitch -> ``mag/heading`` (seed 004 §2.3).

The work is :class:`~ins_gnss_ros.magnetic.compass_front_end.CompassFrontEnd` (ROS-free, the
same for ``trial replay --offline``); this node feeds it ``imu/mag`` samples (base_link axes,
from the ``imu_preprocessor``), the roll and pitch of ``ins/state`` (or the specific force of
``imu/data`` with ``attitude_source: imu_data``), the tilt σ the ekf reports on ``nav/status``
and the position of ``gnss/fix``, and publishes each reading. The front end removes the
vehicle's hard and soft iron (``mag_calibrate_cli`` output or inline parameters; with
``online_calibration.enabled`` fitted in the field as the vehicle turns,
:mod:`ins_gnss_ros.magnetic.field_calibration`, nothing published until that fit's heading
error is small enough, /diagnostics ``calibration`` saying what it waits for, and a given
calibration taken as one from an earlier run), tilt-compensates and gates the sample with the
:class:`~ins_gnss_ros.magnetic.disturbance.DisturbanceDetector`: while a disturbance is flagged
nothing is published and /diagnostics says why. An ``ins/state`` in ALIGNING that no filter has
corrected yet (``correction_sequence`` 0: a strapdown integrating from its initial-attitude
parameters) has no known roll and pitch: nothing is published from it. The roll/pitch error of
the attitude source (``roll_std_deg``, ``pitch_std_deg``, or the larger tilt σ of
``nav/status``) enters the variance and the detector's noise floor: a MEMS INS's tilt, uncertain
by tenths of a degree, cannot show a dip change of half a degree. The WMM
(:mod:`ins_gnss_ros.magnetic.wmm`) at the position (``gnss/fix``, else ``ins/state``, else the
``position.*`` parameters) and at the decimal year of the sample's stamp gives the declination and
the expected field the detector checks against.

The published ``ins_gnss_msgs/Heading`` (:func:`~ins_gnss_ros.nodes.convert.compass_heading`) is
the azimuth of the body x axis, clockwise from true north (or magnetic north with ``reference:
magnetic``), with ``declination`` filled in either case (true = magnetic + declination); pitch and
roll are not observed by a compass: NaN.
"""

from __future__ import annotations

import math
import sys

from ins_gnss_msgs.msg import FilterStatus, Heading, InsState
from sensor_msgs.msg import Imu, MagneticField, NavSatFix, NavSatStatus

from ..io import stamp_to_sec
from ..magnetic.compass_front_end import PARAMS, CompassFrontEnd
from .base import DRIVER_QOS, SENSOR_QOS, STATE_QOS, NavNode, run
from .convert import compass_heading, quat, vec


class MagCompassNode(NavNode):
    PARAMS = PARAMS

    def __init__(self, **kwargs):
        super().__init__("mag_compass", **kwargs)
        self.front = CompassFrontEnd(self.p, self.diag.count, self.diag.set_value,
                                     self.get_logger().info)
        self.pub = self.publisher(Heading, "mag/heading", SENSOR_QOS)
        self.subscribe(MagneticField, "imu/mag", self.on_mag, SENSOR_QOS)
        self.subscribe(NavSatFix, "gnss/fix", self.on_fix, DRIVER_QOS)
        # Read per field sample (and fix), not decoded at the navigation rate.
        self.ins_state = self.subscribe_latest(InsState, "ins/state", SENSOR_QOS,
                                               self.on_ins_state)
        if self.p["attitude_source"] == "imu_data":
            self.subscribe(Imu, "imu/data", self.on_imu, SENSOR_QOS)
        else:
            self.subscribe(FilterStatus, "nav/status", self.on_filter_status, STATE_QOS)

    def on_fix(self, msg: NavSatFix) -> None:
        self.ins_state.handle()  # as if it had been handled when it came: before the fix
        self.front.fix(msg.latitude, msg.longitude, msg.altitude,
                       msg.status.status >= NavSatStatus.STATUS_FIX)

    def on_ins_state(self, msg: InsState) -> None:
        if msg.mode == InsState.MODE_INVALID:
            self.diag.count("invalid ins/state ignored")
            return
        self.front.ins_state(stamp_to_sec(msg.header.stamp), quat(msg.orientation),
                             (msg.latitude, msg.longitude, msg.altitude),
                             msg.mode == InsState.MODE_ALIGNING, msg.correction_sequence)

    def on_filter_status(self, msg: FilterStatus) -> None:
        std = dict(zip(msg.state_names, msg.state_std))
        self.front.tilt_std(std.get("att[0]", math.nan), std.get("att[1]", math.nan))

    def on_imu(self, msg: Imu) -> None:
        self.front.imu(stamp_to_sec(msg.header.stamp), vec(msg.linear_acceleration))

    def on_mag(self, msg: MagneticField) -> None:
        self.ins_state.handle()
        self.stamp_unset_to_arrival(msg.header, "imu/mag")
        reading = self.front.mag(stamp_to_sec(msg.header.stamp), vec(msg.magnetic_field))
        if reading is not None:
            self.pub.publish(compass_heading(reading, msg.header.stamp, self.p["frame_id"],
                                             self.front.true_reference))


def main(args=None) -> int:
    return run(MagCompassNode, args)


if __name__ == "__main__":
    sys.exit(main())
