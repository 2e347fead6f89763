"""CPU time per sample of the imu_preprocessor's ``on_imu`` (docs/results/imu_nodes.md).

A 60 s car trial with a 200 Hz IMU is simulated once (``--bag``, kept for the next run), then its
12,000 ``imu/data_raw`` messages go through ``ImuPreprocessorNode.on_imu`` on an InProcessBus
without subscribers (its outputs are dropped); the best of ``--repeat`` runs (a new node each) is printed
as CPU time (time.process_time: the bench machine is shared, wall time is not comparable).

    PYTHONPATH=<tree>/src/ins_gnss_ros .venv/bin/python bench/bench_imu_preprocessor.py [--cal]

``--cal`` sets a calibration with temperature polynomials, g-sensitivity and a mounting rotation,
and a temperature of 40 degC; without it the sensor is ideal (the profiles' default). Alternate
two source trees on PYTHONPATH for an A/B.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

CALIBRATION = {  # the node test's deliberately bad sensor, as node parameters
    "calibration.gyro.bias": [0.02, -0.01, 0.015, 1e-4, -2e-4, 5e-5],
    "calibration.gyro.scale": [0.01, -0.02, 0.005],
    "calibration.gyro.nonorthogonality": [0.0, 1e-3, -2e-3, 5e-4, 0.0, 1e-3, -1e-3, 2e-3, 0.0],
    "calibration.accel.bias": [0.3, -0.2, 0.1, 2e-3, 1e-3, -1e-3],
    "calibration.accel.scale": [0.02, 0.01, -0.01],
    "calibration.gyro_g_sensitivity": [1e-4 * k for k in range(9)],
    "mounting_rpy_deg": [180.0, 0.0, 90.0],
    "use_temperature": True,
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bag", default="/tmp/bench_imu_preprocessor_bag",
                        help="simulated 60 s trial (made if missing)")
    parser.add_argument("--cal", action="store_true", help="non-trivial calibration, 40 degC")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    import rclpy
    from rclpy.parameter import Parameter

    from ins_gnss_ros.nodes.base import InProcessBus
    from ins_gnss_ros.nodes.imu_preprocessor_node import ImuPreprocessorNode
    from ins_gnss_ros.io import read_bag
    from ins_gnss_ros.trial.simulate import SimOptions, simulate

    bag = Path(args.bag)
    if not bag.exists():
        simulate("car", 60.0, 1, bag, SimOptions())
    msgs = read_bag(bag, ["/imu/data_raw"])
    values = {"rate_hz": 200.0, "nav_rate_hz": 100.0, **(CALIBRATION if args.cal else {})}
    params = [Parameter(k, value=v) for k, v in values.items()]
    context = rclpy.Context()
    rclpy.init(context=context)
    best = float("inf")
    for _ in range(args.repeat):
        bus = InProcessBus()
        node = ImuPreprocessorNode(context=context, bus=bus, parameter_overrides=params)
        if args.cal:
            node.preprocessor.temperature = 40.0
        cpu = time.process_time()
        for m in msgs:
            bus.now_ns = m.t_ns   # the arrival clock of the clock-jump check
            node.on_imu(m.msg)
            bus.drain()
        best = min(best, time.process_time() - cpu)
        node.destroy_node()
    rclpy.shutdown(context=context)
    print(f"{'calibrated' if args.cal else 'ideal'} sensor: {len(msgs)} samples, best of "
          f"{args.repeat}: {best:.3f} s CPU, {best / len(msgs) * 1e6:.1f} us per sample")


if __name__ == "__main__":
    main()
