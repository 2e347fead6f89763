"""``imu_preprocessor`` node: raw IMU and magnetometer samples to calibrated, checked streams.

Every raw ``imu/data_raw`` sample goes through
:class:`~ins_gnss_ros.imu.preprocessor.ImuPreprocessor` (sample rate, sensor clock, time offset, clock jumps, sample checks and bridging, calibration and mounting, the filter's
sensor-error feedback, coning/sculling increments; see there). The node maps the parameters onto
it, counts what it reports on /diagnostics, and publishes the calibrated sample on ``imu/data``
and every completed increment on ``imu/delta``, stamped at the end of its interval.

Magnetometer samples (``imu/mag_raw``) are rotated into ``base_link`` with the same mounting and
published on ``imu/mag``; hard/soft iron belongs to the vehicle and is removed by ``mag_compass``.

The mounting is ``mounting_rpy_deg`` (or the calibration file's); where that is zero and
``/tf_static`` (a URDF through robot_state_publisher, a static_transform_publisher) places the
first sample's ``header.frame_id`` in ``frame_id`` (REP-145: IMU data in the sensor's frame),
that pose is the mounting. The node's own ``frame_id -> imu_frame`` transform is published
unless another node places ``imu_frame``: two publishers of one static transform conflict.
Both are decided at the first sample, with the transforms received by then; where that sample's
frame is not yet placed, the samples (and the magnetometer's meanwhile) wait for its transform
up to :data:`TF_WAIT_S` after the first one arrived and are then handled in order: a URDF's
latched transform reaches a node started with it once DDS has matched the two, which an IMU's
first sample may beat, and the mounting must not depend on that race.

On DDS, with more than two samples an increment and nobody reading ``imu/data``, the samples
before the one that completes an increment wait and are handled together shortly before it is
due (:class:`~ins_gnss_ros.nodes.base.Paced`); the completing one is handled as it comes. A
magnetometer sample arriving meanwhile waits too (up to ~8 ms at 1 kHz).
"""

from __future__ import annotations

import sys

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from ins_gnss_msgs.msg import Heading, ImuDelta, InsCorrection
from sensor_msgs.msg import Imu, MagneticField, Temperature
from tf2_msgs.msg import TFMessage

from ..imu.preprocessor_params import PARAMS, mounting_given, \
    orientation_headings_from_params, preprocessor_from_params
from ..io import NS, codec, field_reader, field_writer, new, ns_to_stamp, set_stamp_ns, \
    stamp_or_arrival, stamp_to_ns
from ..nav.frame_tree import FrameTree, mounting_rpy_deg
from .base import DRIVER_QOS, SENSOR_QOS, STATE_QOS, TF_STATIC_QOS, TF_STATIC_READ_QOS, \
    NavNode, run
from .convert import sensor_errors_of, set_vector3, vec
from .tf_messages import IMU_FRAME_PARAMS, static_tf


#: What is read of every raw sample, straight from its payload.
RAW_FIELDS = ("header.stamp.sec", "header.stamp.nanosec", "angular_velocity.x",
              "angular_velocity.y", "angular_velocity.z", "linear_acceleration.x",
              "linear_acceleration.y", "linear_acceleration.z")
#: What is read of a raw sample for imu/data: the rates' covariances (REP-145).
COVARIANCE_FIELDS = ("angular_velocity_covariance", "linear_acceleration_covariance")
#: imu/data's orientation and its covariance: none estimated (REP-145), identity quaternion.
NO_ORIENTATION = (0.0, 0.0, 0.0, 1.0, -1.0) + (0.0,) * 8

#: ImuPreprocessor events -> diagnostics.
_EVENTS = {"clock_jump": "imu clock jump: stamps corrected by the arrival clock",
           "sensor_clock_restart": "imu sensor clock fit restarted (driver clock step, long gap)",
           "coning_fallback": "coning_method two_sample impossible at the measured rate: "
                              "one_sample used"}


#: How long the first samples wait for /tf_static to place their frame (module doc), s of the
#: arrival clock (the replays' log time): DDS discovery on one host takes 0.1-1 s; a frame no
#: transform places by then gets no mounting, said on /diagnostics.
TF_WAIT_S = 1.0

#: A drift of the IMU's stamps against the arrival clock beyond this (and 3 sigma) is told as
#: one: a crystal's error, 10-100 ms over ten minutes; NTP slews a host's clock by 500 ppm at
#: most, and by far less once it has settled.
ARRIVAL_DRIFT_TOLD = 50e-6


class ImuPreprocessorNode(NavNode):
    PARAMS = PARAMS + IMU_FRAME_PARAMS

    def __init__(self, **kwargs):
        super().__init__("imu_preprocessor", **kwargs)
        p = self.p
        self.preprocessor = preprocessor_from_params(p)
        if self.preprocessor.rate_hz is not None:
            self._report_rates()
        # Read per sample: an attribute, not a parameter-dict lookup.
        self._frame_id = p["frame_id"]
        self.pub_data = self.publisher(Imu, "imu/data", SENSOR_QOS)
        self.pub_delta = self.publisher(ImuDelta, "imu/delta", SENSOR_QOS)
        self.pub_mag = self.publisher(MagneticField, "imu/mag", SENSOR_QOS)
        self.orientation, self._declination = orientation_headings_from_params(
            p, self.preprocessor.calibration.c_bs)
        if self.orientation is not None:
            self.pub_heading = self.publisher(Heading, "imu/heading", SENSOR_QOS)
        # Samples and increments are read and written by field, on DDS and on the bus alike.
        self._read_raw = field_reader("sensor_msgs/msg/Imu", RAW_FIELDS)
        self._read_covariances = field_reader("sensor_msgs/msg/Imu", COVARIANCE_FIELDS)
        self._decode_raw = codec(Imu).decode
        self._write_delta = field_writer("ins_gnss_msgs/msg/ImuDelta", (self._frame_id,))
        self._write_data = field_writer("sensor_msgs/msg/Imu", (self._frame_id,))
        self.raw_input = self.subscribe_paced(Imu, "imu/data_raw", self.on_imu, DRIVER_QOS,
                                              serialized=True)
        self.subscribe(MagneticField, "imu/mag_raw", self.on_mag, DRIVER_QOS)
        if p["use_temperature"]:
            self.subscribe(Temperature, "imu/temperature", self.on_temperature, DRIVER_QOS)
        if p["apply_filter_corrections"]:
            self.subscribe(InsCorrection, "ins/correction", self.on_correction, STATE_QOS)
        self.pub_tf_static = self.publisher(TFMessage, "/tf_static", TF_STATIC_QOS) \
            if p["publish_tf"] else None
        # Read until the first sample settles the mounting and our own transform.
        self.frames = FrameTree()
        self._frames_settled = False
        self._raw_frame = None  # the first sample's header.frame_id
        self._first_stamp_ns = 0  # the first sample's stamp (our transform's)
        self._held = []  # (handler, its arguments) of what waits for its frame, in order
        self._held_since_ns = 0  # the first held sample's arrival
        self.subscribe(TFMessage, "/tf_static", self.on_tf_static, TF_STATIC_READ_QOS)

    def on_tf_static(self, msg: TFMessage) -> None:
        if self._frames_settled:
            return
        self.frames.add_transforms(msg.transforms)
        if self._held and self.frames.pose_in(self._frame_id, self._raw_frame) is not None:
            self._settle_frames()

    def _waits_for_frame(self, raw: bytes, stamp_ns: int, arrival_ns: int) -> bool:
        """Whether a sample before the frames settle waits for /tf_static (module doc)."""
        if self._held:
            return arrival_ns - self._held_since_ns < TF_WAIT_S * NS
        frame = self._raw_frame = self._decode_raw(raw).header.frame_id.lstrip("/")
        self._first_stamp_ns, self._held_since_ns = stamp_ns, arrival_ns
        return bool(frame) and frame != self._frame_id and not mounting_given(self.p) \
            and self.frames.pose_in(self._frame_id, frame) is None

    def _settle_frames(self) -> None:
        """At the first sample, or when its frame is placed or has waited TF_WAIT_S: the
        mounting from /tf_static where the parameters leave it at zero, this node's frame_id ->
        imu_frame transform unless another node places imu_frame (module doc); then what
        waited."""
        self._frames_settled = True
        p, base, frame = self.p, self._frame_id, self._raw_frame
        if frame and frame != base and not mounting_given(p):
            pose = self.frames.pose_in(base, frame)
            if pose is None:
                waited = f" (waited {TF_WAIT_S:g} s)" if self._held else ""
                self.diag.set_value("mounting", f"[0, 0, 0] deg: /tf_static does not place "
                                                f"imu/data_raw's frame '{frame}' in '{base}'"
                                                + waited)
            else:
                rpy = mounting_rpy_deg(pose[0])
                self.preprocessor = preprocessor_from_params({**p, "mounting_rpy_deg": rpy})
                self.orientation, self._declination = orientation_headings_from_params(
                    p, self.preprocessor.calibration.c_bs)
                self.diag.set_value("mounting", f"{rpy} deg: /tf_static's pose of '{frame}' "
                                                f"in '{base}'")
        if self.pub_tf_static is not None and self.frames.places(p["imu_frame"]):
            self.pub_tf_static = None
            self.diag.count(f"{p['imu_frame']} placed by another node's /tf_static: this "
                            "node's transform not published")
        elif self.pub_tf_static is not None:
            self.publish_static_tf(ns_to_stamp(self._first_stamp_ns))
        held, self._held = self._held, []
        for handle, args in held:
            handle(*args)

    def publish_static_tf(self, stamp) -> None:
        """frame_id -> imu_frame (the mounting; the IMU is base_link's origin) on /tf_static,
        once, stamped with the first sample."""
        pub, self.pub_tf_static = self.pub_tf_static, None
        pub.publish(static_tf(stamp, self._frame_id, [
            (self.p["imu_frame"], (0.0, 0.0, 0.0), self.preprocessor.calibration.c_bs)]))

    # -- IMU samples ---------------------------------------------------------------------------
    def on_imu(self, data: bytes) -> None:
        """A raw sample as its CDR payload: the fields used for every sample are read straight
        from it, the rest only when needed."""
        sec, nanosec, wx, wy, wz, fx, fy, fz = self._read_raw(data)
        self.on_sample(sec * NS + nanosec, (wx, wy, wz), (fx, fy, fz), data)

    def on_sample(self, stamp_ns: int, gyro: tuple, accel: tuple, raw: bytes) -> None:
        """One raw sample: its stamp (ns), rates, and its payload."""
        arrival_ns = self.now_ns()
        stamp_ns, unset = stamp_or_arrival(stamp_ns, arrival_ns, "imu/data_raw")
        if unset:
            self.diag.count(unset)
        if not self._frames_settled:
            if self._waits_for_frame(raw, stamp_ns, arrival_ns):
                self._held.append((self._handle_sample, (stamp_ns, arrival_ns, gyro, accel,
                                                         raw)))
                return
            self._settle_frames()
        self._handle_sample(stamp_ns, arrival_ns, gyro, accel, raw)

    def _handle_sample(self, stamp_ns: int, arrival_ns: int, gyro: tuple, accel: tuple,
                       raw: bytes) -> None:
        for out in self.preprocessor.add(stamp_ns, arrival_ns, gyro, accel, raw):
            if out.events:
                self._report(out.events)
            if out.rates is None:
                self.diag.count(f"imu sample rejected: {out.reason}")
                continue
            if out.reason == "gap":
                self.diag.count("imu gap longer than max_bridge_samples: integration restarted")
            elif out.reason == "gap_bridged":
                self.diag.count("imu gap bridged")
                self.diag.set_value("imu samples synthesised", self.preprocessor.synthesised)
            for inc in out.increments:
                self.pub_delta.publish(self._write_delta(
                    *divmod(inc.t_ns, NS), *inc.dtheta.tolist(), *inc.dv.tolist(), inc.dt,
                    inc.angle_var, inc.velocity_var))
            if self.pub_data.wanted():  # the default graph has no imu/data subscriber
                self._publish_data(out.tag, out.t_ns, *out.rates)
            if self.orientation is not None:
                self._publish_heading(out.tag, out.t_ns)
        # Only the sample that completes an increment is on the way to ins/state: the ones
        # before it may wait and be handled together, unless imu/data has a reader. Not
        # with two samples an increment (200 Hz): one sample would wait, a timed wake-up in
        # place of its dispatch (in a pair of live runs in turn with that: the node 1.08x).
        completing = self.preprocessor.completing_stamp(stamp_ns)
        if completing is not None and self.preprocessor.integrator.n_sub > 2 \
                and not self.pub_data.wanted():
            self.raw_input.due(completing)

    def _publish_heading(self, raw, t_ns: int) -> None:
        """imu/heading from the sample's own orientation, when due and valid."""
        if not self.orientation.due(t_ns):
            return
        raw = self._decode_raw(raw)
        o = raw.orientation
        heading = self.orientation.add(t_ns, (o.w, o.x, o.y, o.z), raw.orientation_covariance)
        if heading is None:
            if self.orientation.without_yaw == 1:
                self.diag.count("imu orientation given, but its covariance vouches for no yaw "
                                "(REP-145): not a heading")
            return
        out = new(Heading)
        set_stamp_ns(out.header.stamp, t_ns)
        out.header.frame_id = self._frame_id
        out.azimuth, out.azimuth_variance = heading
        out.pitch = out.roll = out.pitch_variance = out.roll_variance = float("nan")
        out.source = Heading.SOURCE_INERTIAL
        magnetic = self._declination is not None
        out.reference = Heading.REFERENCE_MAGNETIC if magnetic else Heading.REFERENCE_TRUE
        out.declination = self._declination if magnetic else 0.0
        self.pub_heading.publish(out)

    def _report(self, events: tuple) -> None:
        for event in events:
            if event == "rate_measured":
                self._report_rates()
                continue
            if event == "arrival_drift_measured":
                self._report_arrival_drift()
                continue
            if event == "specific_force_judged":
                problem = self.preprocessor.gravity.problem()
                self.diag.set_state(DiagnosticStatus.WARN if problem else DiagnosticStatus.OK,
                                    problem or "ok")
                continue
            self.diag.count(_EVENTS[event])
            if event == "clock_jump":
                self.diag.set_value("imu clock correction, s",
                                    -self.preprocessor.clock.offset_ns / NS)

    def _report_arrival_drift(self) -> None:
        measured = self.preprocessor.arrival_drift.rate()
        if measured is None:
            return
        rate, sigma, span = measured
        text = f"{1e6 * rate:+.1f} +- {1e6 * sigma:.1f} ppm over {span:.0f} s"
        if abs(rate) > max(ARRIVAL_DRIFT_TOLD, 3.0 * sigma):
            text += (": the IMU's stamps drift against this computer's clock (a driver counting "
                     "samples at the nominal rate?), and against GNSS time where the fixes are "
                     "stamped on this clock or on GNSS time")
        self.diag.set_value("imu clock against arrival", text)

    def _report_rates(self) -> None:
        pre = self.preprocessor
        rates = (f"imu {pre.rate_hz:.4f} Hz, imu/delta {pre.nav_rate_hz:.4f} Hz "
                 f"({pre.coning_method})")
        if pre.stamp_scatter_s is not None:   # measured with the rate
            rates += f", stamps scattered {1e3 * pre.stamp_scatter_s:.1f} ms RMS"
        self.diag.set_value("rates", rates)
        self.get_logger().info(rates)

    def _publish_data(self, raw: bytes, t_ns: int, w_b: tuple, f_b: tuple) -> None:
        covariances = self._read_covariances(raw)
        rotate = self.preprocessor.covariance_in_base
        self.pub_data.publish(self._write_data(
            *divmod(t_ns, NS), *NO_ORIENTATION, *w_b, *rotate(covariances[:9]), *f_b,
            *rotate(covariances[9:])))

    def on_temperature(self, msg: Temperature) -> None:
        if not np.isfinite(msg.temperature):
            self.diag.count("non-finite temperature ignored")
            return
        self.preprocessor.temperature = float(msg.temperature)

    def on_correction(self, msg: InsCorrection) -> None:
        if not self.preprocessor.add_sensor_errors(sensor_errors_of(msg)):
            self.diag.count("non-finite sensor correction rejected")

    # -- magnetometer --------------------------------------------------------------------------
    def on_mag(self, msg: MagneticField) -> None:
        self.stamp_unset_to_arrival(msg.header, "imu/mag_raw")
        if self._held:  # rotated by the mounting the IMU's samples wait for
            self._held.append((self._handle_mag, (msg,)))
            return
        self._handle_mag(msg)

    def _handle_mag(self, msg: MagneticField) -> None:
        out = self.preprocessor.add_magnetic(stamp_to_ns(msg.header.stamp),
                                             vec(msg.magnetic_field))
        if isinstance(out, str):
            self.diag.count(f"magnetometer sample rejected: {out}")
            return
        mag = new(MagneticField)
        set_vector3(mag.magnetic_field, out[1])
        set_stamp_ns(mag.header.stamp, out[0])
        mag.header.frame_id = self._frame_id
        mag.magnetic_field_covariance[:] = self.preprocessor.covariance_in_base(msg.magnetic_field_covariance)
        self.pub_mag.publish(mag)


def main(args=None) -> int:
    return run(ImuPreprocessorNode, args)


if __name__ == "__main__":
    sys.exit(main())
