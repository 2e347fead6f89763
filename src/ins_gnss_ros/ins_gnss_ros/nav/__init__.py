"""ROS-free navigation core: Earth model, rotations, strapdown, error model, filter."""
