"""A receiver stream's records -> outputs: dating, stamping, source choice, GST pairing."""
import datetime as dt
import math

import numpy as np
import pytest

from ins_gnss_ros.gnss.observations import (NavSubframe, NmeaErrors, NmeaFix, NmeaHeading,
                                            NmeaRecommended, PvtFix, RawEpoch, RelPosNed,
                                            TimePulse)
from ins_gnss_ros.gnss.receiver import ReceiverStream, Stamp
from ins_gnss_ros.gnss.time import utc_to_gps, week_tow

UTC = dt.datetime(2025, 8, 28, 17, 30, 21)


class Outputs:
    """Records every output as (kind, arguments)."""

    def __init__(self):
        self.got = []

    def __getattr__(self, kind):
        return lambda *args: self.got.append((kind, args))

    def kinds(self):
        return [k for k, _ in self.got]


def _stream(**kwargs):
    out = Outputs()
    return ReceiverStream(out, **kwargs), out


def _gga(time_of_day):
    return NmeaFix("GN", time_of_day, 0.9, 0.1, 10.0, 20.0, 1, 8, 0.9, math.nan)


def _pvt(t_gps):
    return PvtFix(t_gps, UTC, 0.9, 0.1, 30.0, 10.0, np.zeros(3), 1.0, 2.0, 0.1, 3, True, 0, 8,
                  1.2)


def test_nmea_only_stream_dates_gga_by_rmc_and_pairs_gst():
    stream, out = _stream()
    stream.add(_gga(UTC.time()))
    assert out.got == [("report", ("GGA without a known date: dropped", True))]
    out.got.clear()
    stream.add(NmeaRecommended("GN", UTC, True, 0.9, 0.1, 2.0, math.radians(90.0), "A"))
    stream.add(NmeaErrors("GN", (UTC + dt.timedelta(seconds=1)).time(), 1.0, 1.0, 1.0, 0.0,
                          0.5, 0.6, 0.7))
    stream.add(_gga((UTC + dt.timedelta(seconds=2)).time()))
    stream.add(NmeaHeading("GN", 0.5))
    assert out.kinds() == ["publish_velocity", "publish_fix", "publish_heading"]
    (vel, cov, stamp), (gga, errors, fix_stamp), (heading, heading_stamp) = \
        (args for _, args in out.got)
    assert vel == pytest.approx([2.0, 0.0, 0.0]) and cov[0, 0] == pytest.approx(0.25)
    assert stamp == Stamp(utc=UTC)
    assert errors is not None and fix_stamp == Stamp(utc=UTC + dt.timedelta(seconds=2))
    assert heading.azimuth == 0.5 and heading_stamp == fix_stamp  # the latest epoch's


def test_auto_source_prefers_ubx_once_seen_and_stamps_gnss_time():
    stream, out = _stream()
    t = utc_to_gps(UTC)
    stream.add(_pvt(t))
    stream.add(_gga(UTC.time()))          # NMEA fix dropped: NAV-PVT gives the fixes
    assert out.kinds() == ["publish_fix", "publish_velocity"]
    week, tow = week_tow(t)
    assert out.got[0][1][2] == Stamp(week, tow, 18)  # built-in leap seconds until RXM-RAWX
    nmea_fixes, nmea_out = _stream(fix_source="nmea")
    nmea_fixes.add(_pvt(t))
    assert nmea_out.got == []


def test_navigation_data_waits_for_the_first_gnss_time():
    stream, out = _stream()
    stream.add(NavSubframe("G", 1, "1C", 0, (0,) * 10))
    assert out.got == []
    stream.add(RawEpoch(2381, 100.0, 17, True, False, []))
    assert out.kinds() == ["navigation_data", "publish_observations", "publish_time_reference"]
    assert out.got[1][1][2] == Stamp(2381, 100.0, 17)  # the receiver's leap seconds
    out.got.clear()
    stream.add(TimePulse(2381, 101.0, 1e-9, 0))
    stream.add(RawEpoch(2381, 101.0, 17, True, False, []))
    assert out.kinds() == ["publish_time_reference", "publish_observations"]  # TIM-TP now


def test_relposned_heading_only_when_carrier_fixed():
    stream, out = _stream(azimuth_offset=math.radians(90.0))
    rel = RelPosNed(100.0, np.array([100.0, 0.0, 0.0]), 1.0, math.radians(100.0), 0.01, 0.01,
                    True, True, True, True, True, 2)
    stream.add(rel)
    assert out.got == [("report", ("NAV-RELPOSNED before any GNSS time: dropped", True))]
    stream.add(RawEpoch(2381, 99.0, 18, True, False, []))
    out.got.clear()
    stream.add(RelPosNed(**{**rel.__dict__, "carr_soln": 1}))
    stream.add(rel)
    assert out.got[0] == ("report", ("NAV-RELPOSNED not carrier-fixed: no heading", False))
    heading, stamp = out.got[1][1]
    assert math.degrees(heading.azimuth) == pytest.approx(10.0)
    assert stamp == Stamp(2381, 100.0, 18)
