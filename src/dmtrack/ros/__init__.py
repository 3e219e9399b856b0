"""ROS 2 around the run loop: the node ``dmtrack`` (``dmtrack ros2``; ``pip install 'dmtrack[ros]'``).

:mod:`~dmtrack.ros.source` holds the frames the node receives as a live sequence (``TopicFrames``; no ROS import),
:mod:`~dmtrack.ros.node` the rclpy node and the sink that publishes the odometry's results (``DmtrackNode``,
``RosSink``), :mod:`~dmtrack.ros.cli` the command. The odometry and its other sinks know nothing of ROS; bags are
read by :mod:`dmtrack.datasets.rosbag` and written by :mod:`dmtrack.io.rosbag`. rclpy is imported only when the node
starts.
"""
