"""bench/bench_car_oracle.py: a filter started from a stored epoch continues as the original.

The oracle bound of the car drive restarts the filter at each outage start from a stored
(smoothed or forward) state, estimates and covariance. On a simulated car with one outage,
restarting from the forward pass's own last epoch before the outage must reproduce that pass
through the outage: same IMU, same constraint, no measurements.
"""
import importlib.util
import sys

import numpy as np

from ins_gnss_ros.nav.error_model import nav_error
from ins_gnss_ros.nav import NAVIGATING
from conftest import REPO

sys.path.insert(0, str(REPO / "test" / "nav"))
from test_navigator import config, gnss, run, simulate, truth_state  # noqa: E402

_spec = importlib.util.spec_from_file_location("bench_car_oracle",
                                               REPO / "bench" / "bench_car_oracle.py")
ORACLE = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ORACLE)

OUTAGE = (50.0, 65.0)


def test_restart_from_stored_epoch_reproduces_the_coast():
    traj, imu = simulate(duration=70.0)
    measurements = [m for m in gnss(traj, np.random.default_rng(5))
                    if not OUTAGE[0] <= m.t < OUTAGE[1]]
    cfg = config(nhc_sigma=(0.2, 0.5))
    out = run(imu, measurements, cfg)
    # The last epoch before the outage (the last fix is at 49.75 s).
    k = int(np.searchsorted(out.t, OUTAGE[0], side="right")) - 1
    assert out.mode[k] == NAVIGATING
    state = out.state(k)
    nav = ORACLE.StartedNavigator(cfg, state, {n: v[k] for n, v in out.estimates.items()},
                                  out.P[k])
    i = int(np.searchsorted(imu.t, state.t, side="right"))
    j = int(np.searchsorted(imu.t, OUTAGE[1], side="right"))
    nav.add_imu(imu.t[i:j], imu.dtheta[i:j], imu.dv[i:j])
    nav.flush()
    coast = nav.output()
    assert coast.t[0] == state.t
    # Compare at the epochs both passes share inside the outage.
    common, a, b = np.intersect1d(out.t, coast.t, return_indices=True)
    inside = (common > OUTAGE[0]) & (common < OUTAGE[1])
    assert inside.sum() > 100
    diff = [np.linalg.norm(nav_error(coast.state(m), out.state(n))[0][:2])
            for n, m in zip(a[inside], b[inside])]
    drift = [np.linalg.norm(nav_error(out.state(n), truth_state(traj, out.t[n]))[0][:2])
             for n in a[inside]]
    # A real coast (the pass drifts ~1 m from the truth), reproduced to round-off (3e-5 m).
    assert max(drift) > 0.3 and max(diff) < 1e-3, (max(diff), max(drift))
