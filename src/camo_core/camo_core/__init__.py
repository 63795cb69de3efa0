"""The distributed camouflage algorithm (docs/algorithm.md), free of ROS."""
