"""GNSS time scales against calendar arithmetic and the ICD epoch definitions."""
import datetime as dt

import pytest

from ins_gnss_ros.gnss.time import (GPS_EPOCH_POSIX, beidou_to_gps, galileo_to_gps,
                                    glonass_time_of_day, glonass_tod_to_gps, gps_seconds,
                                    gps_to_posix, gps_to_posix_ns, gps_to_utc, leap_seconds,
                                    stream_time, system_week, time_of_week_near, utc_near,
                                    utc_to_gps, utc_to_posix, week_tow, wrap_week_difference)

EPOCH = dt.datetime(1980, 1, 6)


def test_week_and_tow_of_a_known_instant():
    # 2025-08-28 17:30:21.75 UTC: GPS week 2381 began Sunday 2025-08-24; +18 leap seconds.
    t = utc_to_gps(dt.datetime(2025, 8, 28, 17, 30, 21, 750000))
    week, tow = week_tow(t)
    assert week == 2381 and tow == pytest.approx(4 * 86400 + 17 * 3600 + 30 * 60 + 39.75)
    assert gps_seconds(week, tow) == t
    assert gps_to_utc(t, 18) == dt.datetime(2025, 8, 28, 17, 30, 21, 750000)


def test_leap_seconds_table():
    assert leap_seconds(dt.datetime(1980, 1, 6)) == 0
    assert leap_seconds(dt.datetime(2016, 12, 31, 23, 59)) == 17
    assert leap_seconds(dt.datetime(2017, 1, 1)) == 18


def test_other_system_epochs():
    # Galileo OS SIS ICD: GST week 0 starts 1999-08-22 00:00:00 GPST.
    assert galileo_to_gps(0, 0.0) == (dt.datetime(1999, 8, 22) - EPOCH).total_seconds()
    # BDS ICD: BDT starts 2006-01-01 00:00:00 UTC, when GPST - UTC was 14 s.
    assert beidou_to_gps(0, 0.0) == (dt.datetime(2006, 1, 1) - EPOCH).total_seconds() + 14
    # GLONASS time of day 03:00 (Moscow) is 00:00 UTC of the same day.
    ref = utc_to_gps(dt.datetime(2025, 8, 28, 12, 0))
    assert glonass_tod_to_gps(3 * 3600.0, ref, 18) == utc_to_gps(dt.datetime(2025, 8, 28))
    # 01:00 Moscow time on the 29th is 22:00 UTC on the 28th: near a reference at 21:00 UTC.
    ref = utc_to_gps(dt.datetime(2025, 8, 28, 21, 0))
    assert glonass_tod_to_gps(3600.0, ref, 18) == utc_to_gps(dt.datetime(2025, 8, 28, 22))


def test_week_crossover_helpers():
    assert wrap_week_difference(604000.0) == pytest.approx(-800.0)
    assert wrap_week_difference(-604000.0) == pytest.approx(800.0)
    assert wrap_week_difference(100.0) == 100.0
    end = gps_seconds(2381, 604770.0)
    assert time_of_week_near(0.0, end) == gps_seconds(2382, 0.0)
    assert time_of_week_near(604784.0, gps_seconds(2382, 20.0)) == gps_seconds(2381, 604784.0)


def test_posix_of_gps_time_keeps_the_receiver_nanoseconds():
    # 2025-08-28 17:30:21 UTC, GPS week 2381, 18 leap seconds.
    tow = 4 * 86400 + 17 * 3600 + 30 * 60 + 39.000000123
    sec, nanosec = gps_to_posix_ns(2381, tow, 18)
    assert sec == utc_to_posix(dt.datetime(2025, 8, 28, 17, 30, 21)) and nanosec == 123
    assert gps_to_posix_ns(2381, 10.9999999999, 0)[1] == 0  # rounding carried into the second
    assert gps_to_posix(gps_seconds(2381, tow), 18) == pytest.approx(sec + 1.23e-7, abs=1e-6)
    assert gps_to_posix(0.0, 0) == GPS_EPOCH_POSIX


def test_utc_near_dates_a_time_of_day_across_midnight():
    ref = dt.datetime(2025, 8, 28, 23, 59, 59)
    assert utc_near(dt.time(0, 0, 1), ref) == dt.datetime(2025, 8, 29, 0, 0, 1)
    assert utc_near(dt.time(23, 59, 58), ref + dt.timedelta(seconds=2)) == \
        dt.datetime(2025, 8, 28, 23, 59, 58)


def test_system_weeks_and_glonass_day():
    t = gps_seconds(2381, 100.0)
    assert system_week(t, "G") == (2381, 100.0)
    assert system_week(t, "E") == (2381 - 1024, 100.0)
    assert system_week(t, "C") == (2381 - 1356, 86.0)  # BDT = GPST - 14 s
    tod = glonass_time_of_day(t, 18)
    assert tod == pytest.approx((100.0 - 18 + 3 * 3600.0) % 86400.0)
    assert glonass_tod_to_gps(tod, t + 3600.0, 18) == pytest.approx(t)


def test_stream_time_of_records():
    from ins_gnss_ros.gnss.observations import NmeaHeading, NmeaRecommended, RawEpoch

    assert stream_time(RawEpoch(2381, 100.0, 18, True, False)) == gps_seconds(2381, 100.0)
    utc = dt.datetime(2025, 8, 28, 17, 30, 21)
    rmc = NmeaRecommended("GN", utc, True, 0.0, 0.0, 0.0, 0.0, "A")
    assert stream_time(rmc) == utc_to_gps(utc)
    assert stream_time(NmeaHeading("GN", 0.1)) is None
