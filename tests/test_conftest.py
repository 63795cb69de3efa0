"""The order a parallel session sends its tests out in (tests/conftest.py)."""

from __future__ import annotations

from dataclasses import dataclass, field

import conftest


@dataclass
class Item:
    nodeid: str
    slow: bool = False
    fixturenames: list[str] = field(default_factory=list)

    def get_closest_marker(self, name: str):
        return name if name == "slow" and self.slow else None


def test_units_go_out_longest_first_and_those_needing_images_before_the_short_tail(
    monkeypatch,
):
    took = {"t/a.py::long": 40.0, "t/a.py::mid": 9.0, "t/c.py::image_long": 30.0}
    monkeypatch.setattr(conftest, "known_durations", lambda: took)
    items = [
        Item("t/a.py::short"),
        Item("t/c.py::image_long", slow=True, fixturenames=["images", "tmp_path"]),
        Item("t/a.py::mid"),
        Item("t/b.py::slow_unknown", slow=True),
        Item("t/c.py::image_unknown", slow=True, fixturenames=["images"]),
        Item("t/a.py::long"),
    ]
    order = [item.nodeid for item in conftest.in_parallel_order(items)]
    # The images are built as the session starts: their tests wait behind every long unit.
    assert order == [
        "t/a.py::long",
        "t/a.py::mid",
        "t/b.py::slow_unknown",
        "t/c.py::image_long",
        "t/c.py::image_unknown",
        "t/a.py::short",
    ]
