"""The distributed camouflage algorithm (SPEC.md), free of ROS."""
