"""Point the ROS wheels' CMake exports at this machine's Python and NumPy headers.

The ros-jazzy-* wheels are built in a manylinux container, and their generated
CMake files name that container's include directories. colcon builds of
rosidl packages link against those targets, so we rewrite the paths in place.
"""

import pathlib
import sys
import sysconfig

import numpy

WHEEL_PYTHON_INCLUDE = "/opt/python/cp311-cp311/include/python3.11"
WHEEL_NUMPY_INCLUDE = "/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include"


def main(venv: str) -> int:
    replacements = {
        WHEEL_NUMPY_INCLUDE: numpy.get_include(),
        WHEEL_PYTHON_INCLUDE: sysconfig.get_paths()["include"],
    }
    changed = 0
    for path in pathlib.Path(venv, "share").rglob("*.cmake"):
        text = path.read_text()
        new = text
        for old, real in replacements.items():
            new = new.replace(old, real)
        if new != text:
            path.write_text(new)
            changed += 1
    print(f"fix_wheel_paths: rewrote {changed} CMake files", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
