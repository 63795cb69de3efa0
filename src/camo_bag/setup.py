from setuptools import find_packages, setup

package_name = "camo_bag"

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
    description="MCAP bags of camouflage runs: recorder, replay, render, bag info and repair.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "recorder_node = camo_bag.recorder_node:main",
            "camo_replay = camo_bag.replay:main",
            "camo_render = camo_bag.render:main",
            "camo_bag = camo_bag.cli:main",
            "camo_view = camo_bag.view_node:main",
        ],
    },
)
