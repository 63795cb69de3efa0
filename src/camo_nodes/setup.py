from setuptools import find_packages, setup

package_name = "camo_nodes"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    package_data={package_name: ["*.xml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="camo developers",
    maintainer_email="camo@example.org",
    description="The camouflage swarm's nodes: robots, their transport, the monitor.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "robot_node = camo_nodes.robot_node:main",
            "monitor_node = camo_nodes.monitor_node:main",
        ],
    },
)
