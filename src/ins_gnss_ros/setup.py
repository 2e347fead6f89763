from glob import glob

from setuptools import find_packages, setup

PACKAGE = "ins_gnss_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    # the real broadcast ephemeris set the GNSS simulator flies (with its source and licence)
    package_data={"ins_gnss_ros.gnss.ephemeris_data": ["*.json", "SOURCE.md"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        # config/ and launch/ link to the repository's folders so that `colcon build` installs them.
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    description="Integrated inertial/satellite navigation nodes and ROS-free core",
    license="BSD-3-Clause",
    entry_points={"console_scripts": [
        # nodes (ros2 run ins_gnss_ros <name>)
        "imu_preprocessor = ins_gnss_ros.nodes.imu_preprocessor_node:main",
        "strapdown = ins_gnss_ros.nodes.strapdown_node:main",
        "mag_compass = ins_gnss_ros.nodes.mag_compass_node:main",
        "phase_heading = ins_gnss_ros.nodes.phase_heading_node:main",
        "gnss_driver = ins_gnss_ros.nodes.gnss_driver_node:main",
        "gnss_simulator = ins_gnss_ros.nodes.gnss_simulator_node:main",
        "ekf = ins_gnss_ros.nodes.ekf_node:main",
        "live_view = ins_gnss_ros.nodes.live_view_node:main",
        # the main job: simulate, import, replay, evaluate, batch, run
        "trial = ins_gnss_ros.trial.cli:main",
        # calibration tools
        "imu_allan = ins_gnss_ros.tools.allan_cli:main",
        "imu_calibrate = ins_gnss_ros.tools.imu_calibrate_cli:main",
        "mag_calibrate = ins_gnss_ros.tools.mag_calibrate_cli:main",
    ]},
)
