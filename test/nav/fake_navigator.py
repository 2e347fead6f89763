"""A stand-in for the navigator that the aiding front end (nav/aiding.py) feeds: levelled, it
keeps the measurements it is given."""
from types import SimpleNamespace


class RecordingNavigator:
    """Keeps what it is given; ``heading_known`` as the test sets it."""

    config = SimpleNamespace(noise=SimpleNamespace(accel_psd=1e-6, gyro_psd=1e-8), extras={},
                             static_speed=0.1, align_speed=0.5)
    started = True
    space = ()  # (started without extra states: the "td" of arrival stamps is not added)
    solution = None  # (levelled: the gyros' azimuth projects on body z)
    heading_by = None  # (a heading the motion has confirmed, or none)
    heading_unconfirmed = False

    def __init__(self, heading_known: bool = True):
        self.measurements, self.heading_known = [], heading_known
        self.imu_rates_wrong = False
        self.refuted_headings = {}

    def add_measurement(self, m):
        self.measurements.append(m)

    def add_imu(self, *args):
        pass

    def note_imu_rates_wrong(self, wrong):
        self.imu_rates_wrong = wrong

    def attitude_at(self, t):
        return (1.0, 0.0, 0.0, 0.0)  # levelled, facing east: the yaw a run of fixes takes

    def yaw_rate_sigma(self):
        return 0.0

    def tilt_sigma(self):
        return 0.0

    def yaw_scale_sigma(self):
        return 0.0
