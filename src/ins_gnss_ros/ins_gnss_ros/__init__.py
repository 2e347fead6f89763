"""ins-gnss-ros: integrated inertial/satellite navigation as a ROS 2 node graph.

``nav``, ``gnss``, ``magnetic``, ``imu`` and ``sim`` are ROS-free libraries (numpy/scipy only);
``nodes`` holds the thin ROS 2 adapters around them.
"""
