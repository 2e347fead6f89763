"""REP conventions of the published fixes: nav/fix status from the mode and the input's
augmentation, and the driver's RTK float/fixed split (NMEA 0183 v4.11 GGA quality 4 fixed,
5 float; NavSatStatus GBAS_FIX for RTK fixed only)."""
from sensor_msgs.msg import NavSatStatus

from ins_gnss_ros.gnss.observations import NmeaFix
from ins_gnss_ros.nodes.gnss_messages import fix_from_gga
from ins_gnss_ros.nodes.nav_messages import fix_status

S = NavSatStatus


def test_nav_fix_status_from_mode_and_input():
    assert fix_status(False, S.STATUS_GBAS_FIX) == S.STATUS_NO_FIX
    assert fix_status(True, S.STATUS_GBAS_FIX) == S.STATUS_GBAS_FIX
    assert fix_status(True, S.STATUS_SBAS_FIX) == S.STATUS_SBAS_FIX
    assert fix_status(True, S.STATUS_FIX) == S.STATUS_FIX
    assert fix_status(True, S.STATUS_NO_FIX) == S.STATUS_FIX  # navigating on pseudoranges


def test_gga_rtk_fixed_is_gbas_and_float_is_not():
    def status(quality):
        gga = NmeaFix("GN", None, 1.0, 0.5, 10.0, 15.0, quality, 12, 0.8, 1.0)
        return fix_from_gga(gga, None, None, "gnss", S.SERVICE_GPS, 5.0).status.status

    assert [status(q) for q in (0, 1, 2, 4, 5)] == [S.STATUS_NO_FIX, S.STATUS_FIX,
                                                     S.STATUS_SBAS_FIX, S.STATUS_GBAS_FIX,
                                                     S.STATUS_SBAS_FIX]
