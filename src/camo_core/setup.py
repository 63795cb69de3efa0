from setuptools import find_packages, setup

package_name = "camo_core"

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
    description="The camouflage algorithm without ROS, and its reference simulator.",
    license="Apache-2.0",
    entry_points={"console_scripts": ["camo_sim = camo_core.cli.commands:main"]},
)
