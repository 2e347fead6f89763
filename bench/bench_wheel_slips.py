"""Which wheel readings did the filter's gate refuse, against the simulator's slip events?

Reads the ``nav/status`` updates of a ``trial replay`` output of a bag made by ``trial simulate
--scenario car --wheel-odometry`` (default options) and re-draws the same seed's slip record
(sim/wheel_sim.py): how many slipping readings were gated or accepted, and how many readings
were gated without a slip.

Usage::

    .venv/bin/python bench/bench_wheel_slips.py OUT SEED DURATION [DELAY_S]
"""
from __future__ import annotations

import sys
from collections import Counter

import numpy as np

from ins_gnss_ros.sim.scenarios import car
from ins_gnss_ros.sim.wheel_sim import WheelSpec, simulate_wheel
from ins_gnss_ros.trial.inputs import iter_topic
from ins_gnss_ros.trial.simulate import SIM_EPOCH_NS, SimOptions, trajectory_rate


def main() -> int:
    run, seed, duration = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
    delay = float(sys.argv[4]) if len(sys.argv) > 4 else 0.075  # config/sim_car_wheel.yaml
    kinds, gated, accepted = Counter(), [], []
    for m in iter_topic(run + "/bag", "/nav/status"):
        for u in m.msg.updates:
            kinds[(u.name, u.accepted, u.reason)] += 1
            if u.name in ("wheel", "zupt"):
                t = u.stamp.sec + u.stamp.nanosec * 1e-9 - SIM_EPOCH_NS * 1e-9
                (accepted if u.accepted else gated).append(t)
    print("updates (name, accepted, reason):", sorted(kinds.items()))
    o = SimOptions(wheel_odometry=True)
    traj = car(duration=duration, seed=seed, rate=trajectory_rate(o, "car")).trajectory
    spec = WheelSpec(rate=o.wheel_rate, scale_error=o.wheel_scale_error, tick=o.wheel_tick,
                     latency=o.wheel_latency, slip_interval=o.wheel_slip_interval,
                     lever_arm_b=np.array(o.wheel_lever_arm))
    w = simulate_wheel(traj, spec, int(np.random.SeedSequence(seed).generate_state(5)[4]))
    epoch = w.stamp - delay
    bad = w.slipping & (np.abs(w.speed - w.true_speed) > 0.5)

    def found(times, among):
        among = np.sort(np.asarray(among))
        if not len(among):
            return np.zeros(len(times), bool)
        i = np.clip(np.searchsorted(among, times), 1, len(among) - 1)
        return np.minimum(np.abs(among[i] - times), np.abs(among[i - 1] - times)) < 1e-3

    print(f"slipping readings {w.slipping.sum()}, with a speed error > 0.5 m/s {bad.sum()}: "
          f"gated {found(epoch[bad], gated).sum()}, accepted {found(epoch[bad], accepted).sum()}")
    print(f"gated without a slip: {(~found(np.array(gated), epoch[w.slipping])).sum()} "
          f"of {len(gated)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
