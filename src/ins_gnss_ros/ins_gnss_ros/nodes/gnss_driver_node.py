"""``gnss_driver`` node: a u-blox / NMEA 0183 receiver stream -> the ``gnss/*`` topics.

The byte stream comes from the ``source`` URL (:mod:`ins_gnss_ros.gnss.sources`: serial port,
TCP client or server, recorded file at recorded pace or as fast as possible), read by a thread
that waits for bytes (:class:`~ins_gnss_ros.gnss.sources.SourceReader`: a driver without data
costs nothing) and hands them to the executor; :class:`~ins_gnss_ros.gnss.stream.Decoder` frames and
parses it, and :class:`~ins_gnss_ros.gnss.receiver.ReceiverStream` turns the records into
outputs, which the node publishes (it is their ``ReceiverOutputs``).  Published:

* ``gnss/observations``: one GnssObservations per RXM-RAWX epoch (``antenna_id``: run one
  driver per receiver); phase NaN unless valid with the half-cycle ambiguity resolved;
  ``loss_of_lock`` from lock time and half-cycle flag (:class:`~ins_gnss_ros.gnss.lock.LockTracker`).
* ``gnss/fix`` and ``gnss/vel``: from NAV-PVT (ellipsoidal ``height``, covariance from
  hAcc/vAcc/sAcc) or from NMEA GGA (+GST) and RMC; ``fix_source: auto`` uses NMEA only until
  the first NAV-PVT arrives, so a receiver sending both gives one fix per epoch.
  ``gnss/vel`` is ENU in frame ``vel_frame_id`` (default ``enu``).
* ``gnss/ephemeris``: each new or changed broadcast ephemeris assembled from RXM-SFRBX (GPS
  LNAV, Galileo I/NAV, BeiDou D1, GLONASS) by
  :class:`~ins_gnss_ros.gnss.nav_decode.NavDataAssembler`.
* ``gnss/heading``: NAV-RELPOSNED moving-baseline heading, only when relPosValid,
  relPosHeadingValid and carrSoln = fixed; or NMEA HDT (``heading_source``, auto as for fixes);
  mounting offsets from ``heading.*``.
* ``gnss/time_reference``: from TIM-TP (stamp = nominal pulse time, time_ref = pulse time
  corrected by qErr) or, until a TIM-TP arrives, the RXM-RAWX epoch (time_ref = stamp).

Stamps are GNSS time on the ROS (UTC POSIX) axis with the receiver's leap seconds, never receive
time.  Framing faults, unknown messages, records without output and source connection events
go to /diagnostics.
"""

from __future__ import annotations

import math
import sys
from collections import deque

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import TwistWithCovarianceStamped
from ins_gnss_msgs.msg import GnssEphemeris, GnssObservations, Heading
from sensor_msgs.msg import NavSatFix, NavSatStatus, TimeReference

from ..gnss import (NORMAL_EVENTS, Decoder, FileSource, Pacer, PvtFix, ReceiverStream,
                    SourceReader, open_source, stream_time)
from . import gnss_messages as gm
from .base import SENSOR_QOS, STATE_QOS, NavNode, Param, ParameterError, run

#: Decoder counters reported per occurrence on /diagnostics.
_DECODER_FAULTS = (("checksum_errors", "bad checksum"), ("unknown", "unknown message"),
                   ("malformed", "malformed message"))
#: Read size when replaying a file at recorded pace [bytes] (about 1/3 s of a u-blox raw stream).
_PACED_READ_BYTES = 4096


class GnssDriverNode(NavNode):
    PARAMS = (
        Param("source", "serial:///dev/ttyACM0?baud=115200",
              "receiver stream: serial:///dev/X?baud=N, tcp://HOST:PORT, tcp-listen://HOST:PORT "
              "(HOST default 127.0.0.1), file:///PATH?pace=recorded|fast"),
        Param("antenna_id", 0, "GnssObservations.antenna_id of this receiver", 0, 255),
        Param("frame_id", "gnss", "frame of gnss/fix, gnss/heading, gnss/time_reference "
              "(gnss/observations: gnss_antenna_<antenna_id>)"),
        Param("vel_frame_id", "enu", "frame_id of gnss/vel, whose velocity is in ENU axes"),
        Param("fix_source", "auto", "gnss/fix and gnss/vel from UBX NAV-PVT, NMEA GGA/RMC, or "
              "auto (NMEA until the first NAV-PVT)", choices=("auto", "ubx", "nmea")),
        Param("heading_source", "auto", "gnss/heading from UBX NAV-RELPOSNED, NMEA HDT, or auto "
              "(HDT until the first NAV-RELPOSNED)", choices=("auto", "ubx", "nmea")),
        Param("heading.azimuth_offset_deg", 0.0, "azimuth of the antenna baseline (primary to "
              "secondary) in the body frame, clockwise from body x, deg", -360.0, 360.0),
        Param("heading.pitch_offset_deg", 0.0, "elevation of the antenna baseline above the body "
              "x-y plane, deg", -90.0, 90.0),
        Param("heading.nmea_std_deg", 1.0, "1-sigma accuracy assumed for NMEA HDT headings, deg",
              0.001, 180.0),
        Param("nmea.uere_m", 5.0, "range error times HDOP gives the GGA horizontal sigma when no "
              "GST is received, m", 0.01, 1000.0),
        Param("nmea.speed_std_mps", 0.5, "1-sigma horizontal velocity accuracy assumed for NMEA "
              "RMC, m/s", 0.001, 100.0),
        Param("read_max_bytes", 65536, "largest read from the source at once, bytes", 64,
              16_777_216),
        Param("reconnect.initial_s", 0.5, "first wait before reconnecting a lost source, s",
              0.01, 60.0),
        Param("reconnect.max_s", 10.0, "longest wait between reconnection attempts, s",
              0.01, 3600.0),
    )

    def __init__(self, **kwargs):
        super().__init__("gnss_driver", **kwargs)
        p = self.p
        try:
            self.source = open_source(p["source"], notify=self.on_source_event,
                                      retry_initial_s=p["reconnect.initial_s"],
                                      retry_max_s=p["reconnect.max_s"])
        except ValueError as err:
            raise ParameterError(f"parameter 'source': {err}") from None
        paced = isinstance(self.source, FileSource) and self.source.pace == "recorded"
        self.pacer = Pacer() if paced else None
        # Paced replay decodes a little ahead only, so that decoding never delays a due epoch.
        self.read_size = min(p["read_max_bytes"], _PACED_READ_BYTES) if paced \
            else p["read_max_bytes"]
        self.decoder = Decoder()
        self._decoder_seen = {key: 0 for key, _ in _DECODER_FAULTS} | {"garbage_bytes": 0}
        self.receiver = ReceiverStream(
            self, p["fix_source"], p["heading_source"],
            math.radians(p["heading.azimuth_offset_deg"]),
            math.radians(p["heading.pitch_offset_deg"]), math.radians(p["heading.nmea_std_deg"]),
            p["nmea.speed_std_mps"])
        self.pending: deque = deque()
        self.service = NavSatStatus.SERVICE_GPS
        self.pub_obs = self.publisher(GnssObservations, "gnss/observations", SENSOR_QOS)
        self.pub_fix = self.publisher(NavSatFix, "gnss/fix", SENSOR_QOS)
        self.pub_vel = self.publisher(TwistWithCovarianceStamped, "gnss/vel", SENSOR_QOS)
        self.pub_eph = self.publisher(GnssEphemeris, "gnss/ephemeris", STATE_QOS)
        self.pub_heading = self.publisher(Heading, "gnss/heading", SENSOR_QOS)
        self.pub_time = self.publisher(TimeReference, "gnss/time_reference", SENSOR_QOS)
        self.diag.set_value("source", p["source"])
        self.reader = None
        if self.bus is None:  # on a bus whoever drives it calls poll()
            self.reader = SourceReader(
                self.source, self._post, self._on_bytes, self._on_due, self.read_size,
                lambda err: self._post(lambda: self._failed(err)))
            self.reader.start()

    # -- input ------------------------------------------------------------------------------
    def poll(self) -> None:
        """Read what the source has and publish what it completes (paced records first): the
        in-process path, whose driver calls this."""
        self._guarded(self._poll)

    def _poll(self) -> None:
        self._release()
        if not self.pending:
            data = self.source.read(self.read_size, 0.0)
            if data:
                self.feed(data)

    # On DDS the reader thread calls these; the decoding runs on the executor's thread.
    def _post(self, fn) -> None:
        """Run ``fn`` on the executor (from the reader thread), once the node is spun."""
        while (executor := self.executor) is None:  # only until run() adds the node
            if self.reader.sleep(0.05):
                return
        executor.create_task(fn)

    def _on_bytes(self, data: bytes) -> float | None:
        self._guarded(self.feed, data)
        return self._held_back_s()

    def _on_due(self) -> float | None:
        self._guarded(self._release)
        return self._held_back_s()

    def _held_back_s(self) -> float | None:
        """Seconds until the first record the pacer holds back is due, None if none is."""
        if not self.pending or self.pacer is None:
            return None
        return self.pacer.wait_s(stream_time(self.pending[0]))

    def _guarded(self, fn, *args) -> None:
        try:
            fn(*args)
        except Exception as err:  # noqa: BLE001 - a callback must never raise
            self._failed(err)

    def _failed(self, err: Exception) -> None:
        self.diag.count(f"poll failed: {type(err).__name__}")
        self.get_logger().error(f"poll: {err!r}")

    def feed(self, data: bytes) -> None:
        """Decode bytes and publish the records they complete (or queue them for pacing)."""
        self.pending.extend(self.decoder.feed(data))
        self._report_decoder()
        self._release()

    def _release(self) -> None:
        while self.pending:
            if self.pacer is not None and not self.pacer.due(stream_time(self.pending[0])):
                return
            self.handle_record(self.pending.popleft())

    def handle_record(self, record) -> None:
        """Publish what one decoded record gives; an error is counted, never raised."""
        try:
            self.receiver.add(record)
        except Exception as err:  # noqa: BLE001 - a callback must never take the node down
            self.diag.count(f"{type(record).__name__} not published: {type(err).__name__}")
            self.get_logger().error(f"{type(record).__name__}: {err!r}")

    def _report_decoder(self) -> None:
        stats = self.decoder.stats
        for key, what in _DECODER_FAULTS:
            for _ in range(stats[key] - self._decoder_seen[key]):
                self.diag.count(what)
            self._decoder_seen[key] = stats[key]
        if stats["garbage_bytes"] > self._decoder_seen["garbage_bytes"]:
            self.diag.count("garbage bytes skipped")
            self._decoder_seen["garbage_bytes"] = stats["garbage_bytes"]
        for key in ("bytes_in", "frames_ok", "garbage_bytes", "records"):
            self.diag.set_value(key, stats[key])

    def on_source_event(self, event: str, detail: str) -> None:
        normal = event in NORMAL_EVENTS
        self.diag.count(f"source {event}", DiagnosticStatus.OK if normal else DiagnosticStatus.WARN,
                        log=False)
        self.diag.set_value("source_state", event)
        # rclpy ties a severity to the calling line: one line per severity.
        if normal:
            self.get_logger().info(f"{event}: {detail}")
        else:
            self.get_logger().warning(f"{event}: {detail}")

    # -- outputs (ReceiverOutputs) ------------------------------------------------------------
    def publish_observations(self, raw, loss_of_lock, stamp) -> None:
        self.service = gm.service_bits(o.system for o in raw.obs) or self.service
        antenna = self.p["antenna_id"]
        self.pub_obs.publish(gm.observations_msg(raw, antenna, gm.stamp_msg(stamp),
                                                 f"gnss_antenna_{antenna}", loss_of_lock))

    def publish_fix(self, record, errors, stamp) -> None:
        stamp, frame_id = gm.stamp_msg(stamp), self.p["frame_id"]
        if isinstance(record, PvtFix):
            self.pub_fix.publish(gm.fix_from_pvt(record, stamp, frame_id, self.service))
        else:
            self.pub_fix.publish(gm.fix_from_gga(record, errors, stamp, frame_id, self.service,
                                                 self.p["nmea.uere_m"]))

    def publish_velocity(self, vel_enu, cov_enu, stamp) -> None:
        self.pub_vel.publish(gm.twist_msg(vel_enu, cov_enu, gm.stamp_msg(stamp),
                                          self.p["vel_frame_id"]))

    def publish_ephemeris(self, eph, leap, stamp) -> None:
        self.pub_eph.publish(gm.ephemeris_msg(eph, gm.stamp_msg(stamp), leap))

    def publish_heading(self, heading, stamp) -> None:
        self.pub_heading.publish(gm.heading_msg(heading, gm.stamp_msg(stamp), self.p["frame_id"],
                                                Heading.SOURCE_RECEIVER))

    def publish_time_reference(self, stamp, time_ref, source) -> None:
        self.pub_time.publish(gm.time_reference_msg(gm.stamp_msg(stamp), gm.stamp_msg(time_ref),
                                                    self.p["frame_id"], source))

    def navigation_data(self, ephemerides: int, rejected: int) -> None:
        self.diag.set_value("ephemerides", ephemerides)
        self.diag.set_value("nav_data_rejected", rejected)

    def report(self, what: str, warn: bool) -> None:
        if warn:
            self.diag.count(what)
        else:
            self.diag.count(what, DiagnosticStatus.OK, log=False)

    def destroy_node(self):
        if self.reader is not None:
            self.reader.stop()
        self.source.close()
        return super().destroy_node()


def main(args=None) -> int:
    return run(GnssDriverNode, args)


if __name__ == "__main__":
    sys.exit(main())
