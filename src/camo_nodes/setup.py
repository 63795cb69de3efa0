from setuptools import find_packages, setup

package_name = "camo_nodes"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="camo developers",
    maintainer_email="camo@example.org",
    description="Camouflage swarm nodes: robot, monitor, swarm worker, launcher, recorder, replay.",
    license="MIT",
    entry_points={
        "console_scripts": [
            "robot_node = camo_nodes.robot_node:main",
            "monitor_node = camo_nodes.monitor_node:main",
            "swarm_worker = camo_nodes.swarm_worker:main",
            "camo_run = camo_nodes.launcher:main",
            "recorder_node = camo_nodes.recorder_node:main",
            "camo_replay = camo_nodes.replay:main",
            "camo_render = camo_nodes.render:main",
            "camo_bag = camo_nodes.bag_cli:main",
            "droplet_bridge = camo_nodes.droplet_bridge:main",
            "droplet_emulator = camo_nodes.droplet_emulator:main",
        ],
    },
)
