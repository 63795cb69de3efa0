"""A test's way to slow one process of a run without touching camo: on PYTHONPATH, this makes the
worker whose command line holds CAMO_SLOW_CELLS (`--cells=32-63`, say) sleep CAMO_SLOW_SECONDS
before every turn of its host loop's poll. The process stays alive (its heartbeat thread runs
on); only its robots are slow."""

import os
import sys

CELLS = os.environ.get("CAMO_SLOW_CELLS")

if CELLS and CELLS in sys.argv:
    import importlib.abc
    import importlib.util
    import time

    SECONDS = float(os.environ.get("CAMO_SLOW_SECONDS", "1.5"))

    def slow_down(module) -> None:
        poll = module.Transport.poll

        def slow_poll(self):
            time.sleep(SECONDS)
            return poll(self)

        module.Transport.poll = slow_poll

    class Finder(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path, target=None):
            if name != "camo_nodes.transport":
                return None
            sys.meta_path.remove(self)
            spec = importlib.util.find_spec(name)
            load = spec.loader.exec_module

            def exec_module(module):
                load(module)
                slow_down(module)

            spec.loader.exec_module = exec_module
            return spec

    sys.meta_path.insert(0, Finder())
