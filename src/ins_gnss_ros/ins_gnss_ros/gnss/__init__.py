"""ROS-free GNSS: receiver streams and records, time scales, broadcast orbits, single-point
positioning, tight-coupling ranges, the raw-measurement simulator and the carrier-phase
attitude pipeline.

The names in ``__all__`` are the package's public API (what the nodes and ``trial`` use); the
modules hold the rest.  They are imported from their modules on first use: the package spans a
byte-stream decoder and a phase-attitude solver, and a node that only decodes a receiver stream
should not start up scipy.stats and the numba kernels (importing every module costs about 1.4 s,
``gnss.time`` alone 35 ms; the gnss_driver node's import time doubled when they were eager).
"""
from ..lazy_exports import lazy_exports

#: Module -> the public names it defines.
_PUBLIC = {
    "antennas": ("antenna_positions", "mounted_antennas"),
    "attitude": ("AttitudeSolution", "AttitudeSolver", "FixedDoubleDifferences"),
    "clock_model": ("OCXO", "TCXO"),
    "constants": ("BEIDOU", "C_LIGHT", "FIT_HALF_WIDTH_S", "GALILEO", "GLONASS", "GPS",
                  "SECONDS_PER_WEEK", "SIGNAL_ID", "SYSTEM_ID", "UBX_GNSS_ID", "UBX_SIGNALS"),
    "differences": ("NoiseModel",),
    "ephemeris": ("KeplerEphemeris", "accuracy_m"),
    "glonass": ("GlonassEphemeris",),
    "heading": ("GnssHeading", "attitude_heading", "receiver_heading"),
    "lock": ("HalfCycleTracker", "LockTracker"),
    "multipath": ("MultipathModel",),
    "nav_decode": ("NavDataAssembler",),
    "observations": ("NavSubframe", "NmeaErrors", "NmeaFix", "NmeaHeading", "NmeaRecommended",
                     "PvtFix", "RawEpoch", "RelPosNed", "SatObs", "TimePulse"),
    "phase_heading": ("AntennaObservations", "ParsedEpoch", "PhaseHeading", "PhaseHeadingConfig",
                      "lines_of_sight", "parsed_epoch"),
    "ranges": ("RangeConfig", "ephemeris_valid", "satellite_ranges"),
    "receiver": ("ReceiverOutputs", "ReceiverStream", "ReceiverTime", "RecordSources", "Stamp",
                 "errors_at"),
    "simulator": ("GnssSimulator", "SimulatorConfig", "default_start", "solve_fix",
                  "time_reference"),
    "sources": ("NORMAL_EVENTS", "FileSource", "Pacer", "SourceReader", "open_source"),
    "stream": ("Decoder", "split_frames"),
    "time": ("BDT_MINUS_GPST_S", "GPS_EPOCH", "GPS_EPOCH_POSIX", "glonass_time_of_day",
             "gps_seconds", "gps_to_posix", "gps_to_posix_ns", "gps_to_utc", "leap_seconds",
             "stream_time", "system_week", "time_of_week_near", "utc_near", "utc_to_gps",
             "utc_to_posix", "week_tow"),
}
_MODULE_OF = {name: module for module, names in _PUBLIC.items() for name in names}
__getattr__, __dir__, __all__ = lazy_exports(__name__, _MODULE_OF)
