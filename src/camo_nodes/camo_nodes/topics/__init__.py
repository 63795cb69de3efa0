"""What every ROS process of a run shares, so that they always match: topic names and run ids
(`names`), QoS profiles (`qos`), how a process starts rclpy and joins a network (`startup`),
how it finds a run and its setup (`runs`), a node's ROS parameters from their declarations
(`parameters`) and images on the wire (`images`)."""
