"""ROS 2 nodes of the camouflage swarm."""
