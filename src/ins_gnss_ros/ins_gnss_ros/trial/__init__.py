"""ROS-free trial tooling: readers for recorded trials and the evaluation of a navigation run.

* :mod:`.rtklib` -- RTKLIB ``.pos`` solutions and ``.tag`` time-tag files (GPS seconds).
* :mod:`.car_drive` -- the real car drive (IMU csv + RTK truth) in project conventions.
* :mod:`.vessel` -- the simulated vessel in waves (NED parquet) in project conventions.
* :mod:`.outages` -- the ``LEN:PERIOD[:FIRST]`` GNSS outage protocol.
* :mod:`.evaluate` -- errors against truth, statistics, outage drift, NEES, Markdown table.
* :mod:`.plots` -- PNG plots of an evaluation (matplotlib Agg).
"""
