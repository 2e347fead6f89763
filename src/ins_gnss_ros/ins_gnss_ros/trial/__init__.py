"""ROS-free trial tooling: readers for recorded trials and the evaluation of a navigation run.

* :mod:`.rtklib` -- RTKLIB ``.pos`` solutions and ``.tag`` time-tag files (GPS seconds).
* :mod:`.car_drive` -- the real car drive (IMU csv + RTK truth) in project conventions.
* :mod:`.vessel` -- the simulated vessel in waves (NED parquet) in project conventions.
* :mod:`.outages` -- the ``LEN:PERIOD[:FIRST]`` GNSS outage protocol and its windows in a bag.
* :mod:`.profile` -- params files: the graph they select, initialisation from truth.
* :mod:`.inputs` -- what a replay reads from a bag (absolute topic names, truth apart).
* :mod:`.run_folder` -- a replay's output folder, its ``replay.json`` and message counts.
* :mod:`.replay`, :mod:`.processes`, :mod:`.offline` -- ``trial replay`` in-process, as node
  processes on DDS, and through the offline filter (the first two import rclpy when they run).
* :mod:`.evaluate` -- errors against truth, statistics, outage drift, NEES, Markdown table.
* :mod:`.plots` -- PNG plots of an evaluation (matplotlib Agg).
"""
