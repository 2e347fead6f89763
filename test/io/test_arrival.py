"""The arrival forecast of a periodic stream: stamp plus the least delay seen lately."""

from __future__ import annotations

from ins_gnss_ros.io.arrival import ArrivalForecast

MS = 1_000_000


def test_the_forecast_is_the_stamp_plus_the_least_delay():
    forecast = ArrivalForecast(window_ns=1000 * MS)
    assert forecast.arrival(5 * MS) is None
    for k, delay in enumerate([3, 1, 4, 2]):  # ms, scheduling jitter on a transport delay
        forecast.add(k * 10 * MS, k * 10 * MS + delay * MS)
    assert forecast.arrival(100 * MS) == 101 * MS


def test_a_step_of_the_stamping_clock_is_forgotten_after_two_windows():
    forecast = ArrivalForecast(window_ns=100 * MS)
    for k in range(10):   # delay 1 ms
        forecast.add(k * 10 * MS, k * 10 * MS + MS)
    # The stamps step 50 ms back: every later message seems 51 ms late.
    for k in range(10, 40):
        forecast.add(k * 10 * MS - 50 * MS, k * 10 * MS + MS)
        if k < 20:
            assert forecast.arrival(0) == MS     # the window before still holds the old delay
    assert forecast.arrival(0) == 51 * MS
