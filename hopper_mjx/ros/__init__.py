"""ROS I/O: record a batch as ROS 1 / ROS 2 bags, echo a topic, plot a recording."""
