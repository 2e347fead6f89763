"""ROS-free navigation core: Earth model, rotations, strapdown, error model, filter.

The names below are the public API of the filter (the ``ekf`` node, trial/ and the benches use
them); the modules named after the theory (earth, rotations, strapdown, error_model, ...) are
imported by name. Each name is imported on first use: the filter pulls in the compiled kernels
and scipy (``import ins_gnss_ros.nav.navigator`` takes 2.5 s, ``ins_gnss_ros.nav.earth`` 0.2 s),
which users of the light modules (the simulators, the compass) must not pay for.
"""
from ..lazy_exports import lazy_exports

#: Public name -> module of this package that defines it.
_EXPORTS = {
    "Navigator": "navigator",
    "NavigatorConfig": "navigator_config",
    "NavigatorOutput": "recording",
    "point_track": "recording",
    "GnssFix": "measurement_types",
    "GnssVelocity": "measurement_types",
    "HeadingFix": "measurement_types",
    "PhaseDifferences": "measurement_types",
    "SpeedLog": "measurement_types",
    "WheelOdometry": "measurement_types",
    "ZeroVelocity": "measurement_types",
    "SatelliteRanges": "measurement_types",
    "ALIGNING": "modes",
    "NAVIGATING": "modes",
    "DEAD_RECKONING": "modes",
    "NavState": "strapdown",
    "ExtraState": "ekf",
    "rts_smooth": "smoother",
    "SmoothedOutput": "smoother",
}
__getattr__, __dir__, __all__ = lazy_exports(__name__, _EXPORTS)
