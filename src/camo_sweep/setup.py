from setuptools import find_packages, setup

package_name = "camo_sweep"

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
    description="Parameter sweeps of the simulator and the swarm on Dask, into Parquet tables.",
    license="Apache-2.0",
    entry_points={"console_scripts": ["camo_sweep = camo_sweep.cli:main"]},
)
