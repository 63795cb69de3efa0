"""The projector started alone: its image is checked before it waits for a run."""

import subprocess

import pytest
from support import PROCESS, png_bytes, ros_node


def projector(*ros_args: str) -> subprocess.CompletedProcess:
    # No run in its domain: a projector that waited for one would outlast the timeout.
    return ros_node("camo_projector.projector_node", *ros_args, timeout=30)


@pytest.mark.slow(PROCESS)
def test_a_projector_with_a_missing_or_damaged_image_exits_at_once_with_one_line(tmp_path):
    damaged = tmp_path / "damaged.png"
    damaged.write_bytes(png_bytes(16, 16, filter_byte=9))
    cases = {
        str(tmp_path / "missing.png"): "not found",
        str(damaged): "the decoder says 'libpng error: bad adaptive filter value'",
    }
    for image, said in cases.items():
        out = projector("-p", f"image:={image}")
        lines = out.stderr.strip().splitlines()
        assert out.returncode == 2 and len(lines) == 1, out.stderr
        assert lines[0].startswith("projector_node: error: ") and said in lines[0]


@pytest.mark.slow(PROCESS)
def test_a_projector_given_a_parameter_it_has_not_exits_at_once_naming_itself():
    out = projector("-p", "bogus:=1")
    assert out.returncode == 2
    assert out.stderr.strip() == (
        "projector_node: error: projector has no parameter bogus (it has: image, pattern, run_id)"
    )
