from setuptools import find_packages, setup

package_name = "camo_bringup"

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
    description="The bring-up of a camouflage run: the launcher, its workers, benchmarks.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "swarm_worker = camo_bringup.worker:main",
            "camo_run = camo_bringup.launcher:main",
        ],
    },
)
