"""``gnss_driver`` node: a u-blox / NMEA 0183 receiver stream -> the ``gnss/*`` topics.

The byte stream comes from the ``source`` URL (:mod:`ins_gnss_ros.gnss.sources`: serial port,
TCP client or server, recorded file at recorded pace or as fast as possible), polled every
``poll_period_s`` without blocking; :class:`~ins_gnss_ros.gnss.stream.Decoder` frames and
parses it.  Published:

* ``gnss/observations``: one GnssObservations per RXM-RAWX epoch (``antenna_id``: run one
  driver per receiver); phase NaN unless valid with the half-cycle ambiguity resolved;
  ``loss_of_lock`` from lock time and half-cycle flag (:class:`~.gnss_convert.LockTracker`).
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

Stamps are GNSS time on the ROS (UTC POSIX) axis: ``t_gps + 315964800 - leap`` with the
receiver's leap seconds (RXM-RAWX leapS when valid, else the built-in table), never receive
time.  Framing faults, unknown messages and source connection events go to /diagnostics.
"""

from __future__ import annotations

import math
import sys
from collections import deque

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import TwistWithCovarianceStamped
from ins_gnss_msgs.msg import GnssEphemeris, GnssObservations, Heading
from sensor_msgs.msg import NavSatFix, NavSatStatus, TimeReference
from std_msgs.msg import Header

from ..gnss.constants import BEIDOU, GALILEO, GLONASS, GPS
from ..gnss.nav_decode import NavDataAssembler
from ..gnss.observations import (NavSubframe, NmeaErrors, NmeaFix, NmeaHeading, NmeaRecommended,
                                 PvtFix, RawEpoch, RelPosNed, TimePulse)
from ..gnss.sources import NORMAL_EVENTS, FileSource, Pacer, open_source
from ..gnss.stream import Decoder
from ..gnss.time import (gps_seconds, gps_to_utc, leap_seconds, time_of_week_near, utc_to_gps,
                         week_tow)
from ..io import sec_to_stamp
from . import gnss_convert as gc
from .base import SENSOR_QOS, STATE_QOS, NavNode, Param, ParameterError, run

_SERVICE = {GPS: NavSatStatus.SERVICE_GPS, GLONASS: NavSatStatus.SERVICE_GLONASS,
            BEIDOU: NavSatStatus.SERVICE_COMPASS, GALILEO: NavSatStatus.SERVICE_GALILEO}
#: Decoder counters reported per occurrence on /diagnostics.
_DECODER_FAULTS = (("checksum_errors", "bad checksum"), ("unknown", "unknown message"),
                   ("malformed", "malformed message"))
#: Navigation data units kept while no GNSS time is known yet (they need it for week numbers).
_MAX_EARLY_SUBFRAMES = 1024
#: Read size when replaying a file at recorded pace [bytes] (about 1/3 s of a u-blox raw stream).
_PACED_READ_BYTES = 4096
#: Largest GST-to-GGA time difference for using the GST errors as the fix covariance [s].
_GST_MAX_AGE_S = 1.5
#: Vertical velocity variance when NMEA gives none [m^2/s^2] (RMC is horizontal only).
_UNOBSERVED_VAR = 1.0e4


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
        Param("poll_period_s", 0.01, "period of reading the source, s", 0.001, 1.0),
        Param("read_max_bytes", 65536, "largest read from the source per poll, bytes", 64,
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
        self.assembler = NavDataAssembler()
        self.lock = gc.LockTracker()
        self.pending: deque = deque()
        self.early_subframes: deque = deque(maxlen=_MAX_EARLY_SUBFRAMES)
        self.t_gps: float | None = None      # latest GNSS epoch [GPS s]
        self.receiver_leap: int | None = None
        self.utc_ref = None                  # latest UTC datetime (dates GGA times)
        self.last_stamp = None               # stamp of the latest epoch (for HDT)
        self.gst: NmeaErrors | None = None
        self.service = NavSatStatus.SERVICE_GPS
        self.seen = set()                    # record kinds seen, for the auto sources
        self._azimuth_offset = math.radians(p["heading.azimuth_offset_deg"])
        self._pitch_offset = math.radians(p["heading.pitch_offset_deg"])
        self._handlers = {RawEpoch: self.on_raw, PvtFix: self.on_pvt, NavSubframe: self.on_subframe,
                          RelPosNed: self.on_relposned, TimePulse: self.on_time_pulse,
                          NmeaFix: self.on_gga, NmeaRecommended: self.on_rmc,
                          NmeaErrors: self.on_gst, NmeaHeading: self.on_hdt}
        self.pub_obs = self.publisher(GnssObservations, "gnss/observations", SENSOR_QOS)
        self.pub_fix = self.publisher(NavSatFix, "gnss/fix", SENSOR_QOS)
        self.pub_vel = self.publisher(TwistWithCovarianceStamped, "gnss/vel", SENSOR_QOS)
        self.pub_eph = self.publisher(GnssEphemeris, "gnss/ephemeris", STATE_QOS)
        self.pub_heading = self.publisher(Heading, "gnss/heading", SENSOR_QOS)
        self.pub_time = self.publisher(TimeReference, "gnss/time_reference", SENSOR_QOS)
        self.diag.set_value("source", p["source"])
        if self.bus is None:  # on a bus whoever drives it calls poll()
            self.create_timer(p["poll_period_s"], self.poll)

    # -- input ------------------------------------------------------------------------------
    def poll(self) -> None:
        """Read what the source has and publish what it completes (paced records first)."""
        try:
            self._release()
            if not self.pending:
                data = self.source.read(self.read_size, 0.0)
                if data:
                    self.feed(data)
        except Exception as err:  # noqa: BLE001 - the timer callback must never raise
            self.diag.count(f"poll failed: {type(err).__name__}")
            self.get_logger().error(f"poll: {err!r}")

    def feed(self, data: bytes) -> None:
        """Decode bytes and publish the records they complete (or queue them for pacing)."""
        self.pending.extend(self.decoder.feed(data))
        self._report_decoder()
        self._release()

    def _release(self) -> None:
        while self.pending:
            record = self.pending[0]
            if self.pacer is not None:
                t = gc.stream_time(record)
                if t is not None:
                    if self.pacer.wait_s(t) > 0.0:
                        return
                    self.pacer.released(t)
            self.pending.popleft()
            self.handle_record(record)

    def handle_record(self, record) -> None:
        """Publish what one decoded record gives; an error is counted, never raised."""
        handler = self._handlers.get(type(record))
        if handler is None:
            return  # GSA, GSV, VTG: decoded, nothing to publish
        try:
            handler(record)
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

    # -- time ---------------------------------------------------------------------------------
    def leap(self, t_gps: float) -> int:
        """GPST - UTC [s]: the receiver's, else the built-in table's at that time."""
        if self.receiver_leap is not None:
            return self.receiver_leap
        return leap_seconds(gps_to_utc(t_gps, 18))

    def _set_time(self, t_gps: float) -> None:
        """Advance the latest GNSS time; the first one releases the early navigation data."""
        first = self.t_gps is None
        if first or t_gps > self.t_gps:
            self.t_gps = t_gps
        while first and self.early_subframes:
            self.on_subframe(self.early_subframes.popleft())

    def stamp(self, t_gps: float, tow: float | None = None):
        """ROS stamp of a GNSS time [GPS s] (exact when the time of week ``tow`` is given)."""
        week, tow_of_t = week_tow(t_gps)
        stamp = gc.gps_stamp(week, tow_of_t if tow is None else tow, self.leap(t_gps))
        self.last_stamp = stamp
        return stamp

    def _use(self, kind: str, ubx_kind: str, param: str) -> bool:
        """Whether records of ``kind`` feed the output selected by ``param`` (ubx/nmea/auto)."""
        self.seen.add(kind)
        choice = self.p[param]
        if choice == "auto":
            return kind == ubx_kind or ubx_kind not in self.seen
        return (kind == ubx_kind) == (choice == "ubx")

    # -- UBX ----------------------------------------------------------------------------------
    def on_raw(self, raw: RawEpoch) -> None:
        if raw.leap_valid:
            self.receiver_leap = raw.leap_s
        self._set_time(raw.t_gps)
        stamp = self.stamp(raw.t_gps, raw.tow)
        services = {_SERVICE[o.system] for o in raw.obs if o.system in _SERVICE}
        if services:
            self.service = sum(services)
        self.pub_obs.publish(gc.observations_msg(
            raw, self.p["antenna_id"], stamp, f"gnss_antenna_{self.p['antenna_id']}",
            self.lock.update(raw)))
        if "TimePulse" not in self.seen:
            self.pub_time.publish(TimeReference(
                header=Header(stamp=stamp, frame_id=self.p["frame_id"]), time_ref=stamp,
                source="gnss"))

    def on_pvt(self, pvt: PvtFix) -> None:
        if not math.isfinite(pvt.t_gps):
            self.diag.count("NAV-PVT without valid date/time: dropped")
            return
        self._set_time(pvt.t_gps)
        if not self._use("PvtFix", "PvtFix", "fix_source"):
            return
        stamp = self.stamp(pvt.t_gps)
        self.pub_fix.publish(gc.fix_from_pvt(pvt, stamp, self.p["frame_id"], self.service))
        self.pub_vel.publish(gc.twist_msg(pvt.vel_enu, [pvt.s_acc ** 2] * 3, stamp,
                                          self.p["vel_frame_id"]))

    def on_subframe(self, unit: NavSubframe) -> None:
        if self.t_gps is None:
            self.early_subframes.append(unit)
            return
        leap = self.leap(self.t_gps)
        for eph in self.assembler.add(unit, self.t_gps, leap):
            self.pub_eph.publish(gc.ephemeris_msg(eph, self.stamp(self.t_gps), leap))
        self.diag.set_value("ephemerides", len(self.assembler.ephemerides))
        self.diag.set_value("nav_data_rejected", self.assembler.stats["rejected"])

    def on_relposned(self, rel: RelPosNed) -> None:
        if not self._use("RelPosNed", "RelPosNed", "heading_source"):
            return
        if self.t_gps is None:
            self.diag.count("NAV-RELPOSNED before any GNSS time: dropped")
            return
        if not (rel.rel_pos_valid and rel.heading_valid and rel.carr_soln == 2):
            self.diag.count("NAV-RELPOSNED not carrier-fixed: no heading", DiagnosticStatus.OK,
                            log=False)
            return
        t = time_of_week_near(rel.itow_s, self.t_gps)
        self.pub_heading.publish(gc.heading_msg(
            rel.azimuth, rel.acc_azimuth, self.stamp(t), self.p["frame_id"],
            self._azimuth_offset, gc.relposned_elevation(rel), self._pitch_offset,
            # NAV-RELPOSNED's accD is not decoded: the vertical error is taken as twice the
            # horizontal cross-baseline one, as is typical of GNSS geometry.
            2.0 * rel.acc_azimuth, rel.length))

    def on_time_pulse(self, tp: TimePulse) -> None:
        self.seen.add("TimePulse")
        # time base 1: UTC week and time of week, which count from the GPS epoch without leaps
        leap = 0 if tp.time_base == 1 else self.leap(gps_seconds(tp.week, tp.tow))
        self.pub_time.publish(TimeReference(
            header=Header(stamp=gc.gps_stamp(tp.week, tp.tow, leap), frame_id=self.p["frame_id"]),
            time_ref=gc.gps_stamp(tp.week, tp.tow + tp.q_err_s, leap), source="gnss_pps"))

    # -- NMEA ---------------------------------------------------------------------------------
    def _utc_reference(self):
        if self.utc_ref is not None:
            return self.utc_ref
        if self.t_gps is not None:
            return gps_to_utc(self.t_gps, self.leap(self.t_gps))
        return None

    def on_rmc(self, rmc: NmeaRecommended) -> None:
        if rmc.utc is not None:
            self.utc_ref = rmc.utc
        if not self._use("NmeaRecommended", "PvtFix", "fix_source") or not rmc.valid \
                or rmc.utc is None:
            return
        if not math.isfinite(rmc.course):
            self.diag.count("RMC without course: no velocity", DiagnosticStatus.OK, log=False)
            return
        var_h = self.p["nmea.speed_std_mps"] ** 2
        stamp = sec_to_stamp(gc.utc_to_posix(rmc.utc))
        self.last_stamp = stamp
        self.pub_vel.publish(gc.twist_msg(gc.rmc_velocity(rmc), [var_h, var_h, _UNOBSERVED_VAR],
                                          stamp, self.p["vel_frame_id"]))

    def on_gst(self, gst: NmeaErrors) -> None:
        self.gst = gst

    def on_gga(self, gga: NmeaFix) -> None:
        if not self._use("NmeaFix", "PvtFix", "fix_source"):
            return
        ref = self._utc_reference()
        if ref is None or gga.utc_time is None:
            self.diag.count("GGA without a known date: dropped")
            return
        if not math.isfinite(gga.geoid_sep):
            self.diag.count("GGA without geoid separation (no ellipsoidal height): dropped")
            return
        utc = gc.utc_near(gga.utc_time, ref)
        errors = None
        if self.gst is not None and self.gst.utc_time is not None:
            gap = abs((gc.utc_near(self.gst.utc_time, utc) - utc).total_seconds())
            errors = self.gst if gap <= _GST_MAX_AGE_S else None
        stamp = sec_to_stamp(gc.utc_to_posix(utc))
        self.last_stamp = stamp
        self._set_time(utc_to_gps(utc, self.receiver_leap))
        self.pub_fix.publish(gc.fix_from_gga(gga, errors, stamp, self.p["frame_id"],
                                             self.service, self.p["nmea.uere_m"]))

    def on_hdt(self, hdt: NmeaHeading) -> None:
        if not self._use("NmeaHeading", "RelPosNed", "heading_source"):
            return
        if not math.isfinite(hdt.azimuth) or self.last_stamp is None:
            self.diag.count("HDT without heading or epoch time: dropped")
            return
        self.pub_heading.publish(gc.heading_msg(
            hdt.azimuth, math.radians(self.p["heading.nmea_std_deg"]), self.last_stamp,
            self.p["frame_id"], self._azimuth_offset))

    def destroy_node(self):
        self.source.close()
        return super().destroy_node()


def main(args=None) -> int:
    return run(GnssDriverNode, args)


if __name__ == "__main__":
    sys.exit(main())
