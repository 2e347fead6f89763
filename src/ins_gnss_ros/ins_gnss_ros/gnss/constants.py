"""Physical and system constants of the GNSS constellations.

Every constant names the interface control document that defines it, because the
constellations differ in the last digits (e.g. GPS and Galileo use different values
of the Earth's gravitational constant in their orbit models, and a mismatch is a
metre-level error).
"""
import math

#: Speed of light in vacuum [m/s] (IS-GPS-200 §20.3.4.3, Galileo OS SIS ICD §5.1.1).
C_LIGHT = 299792458.0

#: WGS-84 Earth rotation rate used by the GPS orbit model [rad/s] (IS-GPS-200 Table 20-IV).
OMEGA_E = 7.2921151467e-5
#: GPS value of the Earth's gravitational constant [m^3/s^2] (IS-GPS-200 Table 20-IV).
GM_GPS = 3.986005e14
#: Galileo value of the Earth's gravitational constant [m^3/s^2] (Galileo OS SIS ICD §5.1.1).
#: The Galileo ICD uses the same Earth rotation rate as GPS.
GM_GAL = 3.986004418e14
#: BeiDou (CGCS2000) gravitational constant and rotation rate (BDS-SIS-ICD-B1I 3.0 §5.2.4.9).
GM_BDS = 3.986004418e14
OMEGA_E_BDS = 7.2921150e-5

#: PZ-90 constants used by the GLONASS orbit integration (GLONASS ICD ed. 5.1, Table 3.2 / A.3.1.2).
GM_GLO = 398600.4418e9
OMEGA_E_GLO = 7.292115e-5
A_E_GLO = 6378136.0
J2_GLO = 1082625.75e-9

#: Seconds per GPS week.
SECONDS_PER_WEEK = 604800.0
#: Half a week [s]: the range of a correctly wrapped time difference (IS-GPS-200 §20.3.3.4.3).
HALF_WEEK = 302400.0

#: Half-width of the broadcast fit interval of Keplerian ephemerides around toe [s]
#: (IS-GPS-200 §20.3.4.4: 4-hour fit interval; Galileo I/NAV and BeiDou are used likewise).
FIT_HALF_WIDTH_S = 7200.0

#: One semicircle in radians: GPS and Galileo broadcast angles in semicircles.
SEMICIRCLE = math.pi

# Carrier frequencies [Hz] (IS-GPS-200, IS-GPS-705, Galileo OS SIS ICD, BDS ICDs, GLONASS ICD).
FREQ_L1 = 1575.42e6
FREQ_L2 = 1227.60e6
FREQ_L5 = 1176.45e6
FREQ_E1 = FREQ_L1
FREQ_E5A = FREQ_L5
FREQ_E5B = 1207.140e6
FREQ_E6 = 1278.75e6
FREQ_B1I = 1561.098e6
FREQ_B1C = FREQ_L1
FREQ_B2A = FREQ_L5
FREQ_B2I = FREQ_E5B
FREQ_B3I = 1268.52e6
#: GLONASS FDMA: f = base + k * step, k the frequency slot -7..+6 (GLONASS ICD §3.3.1.4).
FREQ_G1_BASE, FREQ_G1_STEP = 1602.0e6, 0.5625e6
FREQ_G2_BASE, FREQ_G2_STEP = 1246.0e6, 0.4375e6

#: Systems, by RINEX letter.
GPS, SBAS, GALILEO, BEIDOU, QZSS, GLONASS, NAVIC = "G", "S", "E", "C", "J", "R", "I"

#: u-blox gnssId -> system letter (u-blox F9/X20 interface description, "GNSS identifiers").
UBX_GNSS_ID = {0: GPS, 1: SBAS, 2: GALILEO, 3: BEIDOU, 5: QZSS, 6: GLONASS, 7: NAVIC}

#: (u-blox gnssId, sigId) -> (signal name as in RINEX 3 observation codes, carrier [Hz]).
#: GLONASS entries carry the base frequency; the slot offset is added by `carrier_frequency`.
UBX_SIGNALS = {
    (0, 0): ("1C", FREQ_L1), (0, 3): ("2L", FREQ_L2), (0, 4): ("2S", FREQ_L2),
    (0, 6): ("5I", FREQ_L5), (0, 7): ("5Q", FREQ_L5),
    (1, 0): ("1C", FREQ_L1),
    (2, 0): ("1C", FREQ_E1), (2, 1): ("1B", FREQ_E1), (2, 3): ("5I", FREQ_E5A),
    (2, 4): ("5Q", FREQ_E5A), (2, 5): ("7I", FREQ_E5B), (2, 6): ("7Q", FREQ_E5B),
    (2, 8): ("6B", FREQ_E6), (2, 9): ("6C", FREQ_E6), (2, 10): ("6A", FREQ_E6),
    (3, 0): ("2I", FREQ_B1I), (3, 1): ("2I", FREQ_B1I), (3, 2): ("7I", FREQ_B2I),
    (3, 3): ("7I", FREQ_B2I), (3, 4): ("6I", FREQ_B3I), (3, 5): ("1P", FREQ_B1C),
    (3, 6): ("1D", FREQ_B1C), (3, 7): ("5P", FREQ_B2A), (3, 8): ("5D", FREQ_B2A),
    (3, 10): ("6I", FREQ_B3I),
    (5, 0): ("1C", FREQ_L1), (5, 1): ("1Z", FREQ_L1), (5, 4): ("2S", FREQ_L2),
    (5, 5): ("2L", FREQ_L2), (5, 8): ("5I", FREQ_L5), (5, 9): ("5Q", FREQ_L5),
    (6, 0): ("1C", FREQ_G1_BASE), (6, 2): ("2C", FREQ_G2_BASE),
    (7, 0): ("5A", FREQ_L5),
}
#: RINEX system letter -> u-blox gnssId (the numbering of ins_gnss_msgs/GnssObservations).
SYSTEM_ID = {letter: gnss_id for gnss_id, letter in UBX_GNSS_ID.items()}
#: (system letter, RINEX signal code) -> u-blox sigId. Where u-blox has two ids for one code
#: (BeiDou B1I/B2I/B3I D1 and D2), the lower (D1) id is used.
SIGNAL_ID = {(UBX_GNSS_ID[gid], code): sid  # descending: the lowest sigId is written last
             for (gid, sid), (code, _) in sorted(UBX_SIGNALS.items(), reverse=True)}


def carrier_frequency(system, signal, freq_slot=0):
    """Carrier frequency of a signal.

    Parameters
    ----------
    system : str
        RINEX system letter.
    signal : str
        RINEX 3 two-character observation code (band digit and attribute), e.g. "1C".
    freq_slot : int
        GLONASS FDMA frequency number k (-7..+6); ignored for CDMA systems.

    Returns
    -------
    float
        Carrier frequency [Hz], NaN when the combination is unknown.
    """
    if system == GLONASS:
        if signal.startswith("1"):
            return FREQ_G1_BASE + freq_slot * FREQ_G1_STEP
        if signal.startswith("2"):
            return FREQ_G2_BASE + freq_slot * FREQ_G2_STEP
        return math.nan
    for (gnss_id, _), (name, freq) in UBX_SIGNALS.items():
        if UBX_GNSS_ID.get(gnss_id) == system and name == signal:
            return freq
    return math.nan
