"""The algorithm package must import and run where ROS is not installed at all."""

import subprocess
import sys

BLOCK_ROS = """
import importlib.abc, sys
class NoRos(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in ('rclpy', 'rosidl_runtime_py', 'camo_msgs', 'std_msgs', 'sensor_msgs'):
            raise ImportError('ROS is blocked in this test: ' + name)
sys.meta_path.insert(0, NoRos())
import pkgutil, importlib, camo_core
names = [m.name for m in pkgutil.iter_modules(camo_core.__path__)]
for name in names:
    importlib.import_module('camo_core.' + name)
from camo_core.params import CamoParams
from camo_core.simulator import simulate
from camo_core.backgrounds import background
from camo_core.sensing import sense_image
result = simulate(CamoParams(), sense_image(background('forest'), 8, 8, 'paper'))
assert 'rclpy' not in sys.modules
print(len(names), result.majority_pattern)
"""


def test_camo_core_imports_and_runs_with_ros_blocked():
    out = subprocess.run(
        [sys.executable, "-c", BLOCK_ROS], capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0, out.stderr
    count, pattern = out.stdout.split()
    assert int(count) >= 10 and pattern == "vertical"
