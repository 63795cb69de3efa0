"""The ROS image's Dockerfile, for stock ROS tools (not built here: no registry serves it)."""

from support import ROOT


def test_dockerfile_builds_on_ros_jazzy_and_copies_files_that_exist():
    dockerfile = ROOT / "docker" / "ros.Dockerfile"
    lines = [line.strip() for line in dockerfile.read_text().splitlines()]
    assert lines[[line.startswith("FROM") for line in lines].index(True)].startswith(
        "FROM ros:jazzy"
    )
    assert "ros-jazzy-rosbag2-storage-mcap" in dockerfile.read_text()
    copies = [line.split()[1:-1] for line in lines if line.startswith("COPY")]
    assert copies
    for sources in copies:
        for source in sources:
            assert (ROOT / source).exists(), source
    for requirement in ("colcon build", "camo_nodes"):
        assert requirement in dockerfile.read_text()
