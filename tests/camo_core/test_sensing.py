"""Sensing: grey values, block means, measurement noise, real readings, calibration, contrast."""

import json
import os
import threading

import cv2
import numpy as np
import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st
from support import COMPUTE, PROCESS

from camo_core.algorithm import sensing
from camo_core.algorithm.params import ParameterError
from camo_core.algorithm.sensing import Calibration, rgb_to_gray, to_gray
from camo_core.inputs.files import shown
from camo_core.inputs.images import ImageError


def test_block_means_are_unrounded_area_averages():
    gray = np.zeros((4, 4), np.uint8)
    gray[0, 0] = 1  # block (0, 0) mean is 0.25, which a uint8 resize would round away
    gray[2:, 2:] = 200
    means = sensing.block_means(gray, 2, 2)
    assert means.dtype == np.float64
    assert means.tolist() == [[0.25, 0.0], [0.0, 200.0]]


def test_paper_grey_is_opencv_luma_and_droplet_grey_is_red_green_mean():
    bgr = np.zeros((2, 2, 3), np.uint8)
    bgr[..., 0], bgr[..., 1], bgr[..., 2] = 10, 101, 250  # B, G, R
    assert np.array_equal(
        sensing.to_gray(bgr, "paper"), cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY).astype(float)
    )
    assert sensing.to_gray(bgr, "droplet")[0, 0] == 0.5 * 250 + 0.5 * 101


def test_grey_image_is_used_as_is_by_both_profiles():
    gray = np.arange(16, dtype=np.uint8).reshape(4, 4)
    assert np.array_equal(sensing.to_gray(gray, "paper"), sensing.to_gray(gray, "droplet"))


def test_noise_replaces_about_rho_of_the_robots_with_whole_grey_levels():
    sensed = np.full((100, 100), 0.5)
    noisy = sensing.apply_noise(sensed, seed=3, rho_meas=0.2)
    replaced = noisy != 0.5
    assert abs(replaced.mean() - 0.2) < 0.02
    assert np.all(noisy[replaced] == np.floor(noisy[replaced])) and noisy.max() <= 255
    assert sensing.noisy_value(3, 42, 0.5, 0.2) == noisy.ravel()[42]


def test_an_image_smaller_than_the_grid_is_refused():
    with pytest.raises(ImageError, match="smaller"):
        sensing.block_means(np.zeros((5, 5)), 8, 8)


@pytest.mark.parametrize("profile", ["paper", "droplet"])
def test_a_grey_reading_gives_its_own_value_in_both_profiles(profile):
    for v in (0, 1, 77, 128, 254, 255):
        assert rgb_to_gray(v, v, v, profile) == v


def test_a_colour_reading_is_grey_as_the_image_pixel_would_be():
    for r, g, b in ((200, 10, 30), (0, 255, 7), (13, 14, 250)):
        pixel = np.array([[[b, g, r]]], np.uint8)
        assert rgb_to_gray(r, g, b, "paper") == to_gray(pixel, "paper")[0, 0]
        assert rgb_to_gray(r, g, b, "droplet") == 0.5 * r + 0.5 * g
    with pytest.raises(ValueError):
        rgb_to_gray(256, 0, 0, "paper")


def test_calibration_is_identity_by_default_and_reads_yaml(tmp_path):
    assert Calibration().apply(123.5) == 123.5
    path = tmp_path / "cal.yaml"
    path.write_text("gain: 1.1\noffset: -5\n")
    cal = Calibration.from_yaml(path)
    assert (
        cal.apply(100) == pytest.approx(105.0) and cal.apply(250) == 255.0 and cal.apply(1) == 0.0
    )
    path.write_text("gain: [1\n")
    with pytest.raises(ParameterError, match="not YAML"):
        Calibration.from_yaml(path)
    path.write_text("gain: 0\n")
    with pytest.raises(ParameterError, match=r"gain must be in \(0, 1e\+06\]"):
        Calibration.from_yaml(path)


@pytest.mark.parametrize(
    ("text", "said"),
    [
        ('gain: "1"\n', "gain must be a number (got '1')"),
        ("gain: true\n", "gain must be a number (got true)"),
        ("gain: 1e44\n", "gain must be in (0, 1e+06] (got 1e+44)"),
        ("offset: -1e300\n", "offset must be within +-1e+06"),
        ("gain: 1:00\n", "(line 1): '1:00' is a base-60 number"),
        ("gain: 1\noffset: 0\ngain: 5\n", "(line 3): the key 'gain' is given twice"),
        ("gain: " + "9" * 5000 + "\n", "an integer of 5000 digits"),
        ("gain: 2\n---\ngain: 3\n", "more than one document"),
    ],
)
def test_a_calibration_takes_numbers_in_range_read_strictly(tmp_path, text, said):
    path = tmp_path / "cal.yaml"
    path.write_text(text)
    with pytest.raises(ParameterError) as caught:
        Calibration.from_yaml(path)
    assert said in str(caught.value) and "\n" not in str(caught.value)
    assert shown(path) in str(caught.value)  # a long temporary path shown shortened


@pytest.mark.parametrize("special", ["/dev/zero", "/dev/urandom", "fifo"])
def test_a_calibration_that_is_a_device_or_a_fifo_is_refused_not_a_hang(tmp_path, special):
    if special == "fifo":
        special = str(tmp_path / "cal.yaml")
        os.mkfifo(special)
    said: list[str] = []

    def read():
        try:
            Calibration.from_yaml(special)
        except ParameterError as exc:
            said.append(str(exc))

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(10)
    assert said == [f"the calibration {shown(special)} is not a regular file"]


@pytest.mark.slow(COMPUTE)
@given(
    content=st.one_of(
        st.binary(max_size=64),
        st.dictionaries(
            st.sampled_from(["gain", "offset", "other"]),
            st.one_of(
                st.none(), st.booleans(), st.floats(), st.text(max_size=5), st.lists(st.integers())
            ),
            max_size=3,
        ).map(lambda d: yaml.safe_dump(d).encode()),
    )
)
def test_any_calibration_file_reads_or_is_refused_in_one_line(tmp_path_factory, content):
    path = tmp_path_factory.mktemp("cal") / "calibration.yaml"
    path.write_bytes(content)
    try:
        cal = Calibration.from_yaml(path)
    except ParameterError as exc:
        assert "\n" not in str(exc)
    else:
        assert 0.0 <= cal.apply(128.0) <= 255.0


def test_contrast_pulls_every_value_toward_the_images_mean():
    image = np.array([[0, 100], [200, 100]], np.uint8)  # mean 100
    assert np.array_equal(sensing.with_contrast(image, 1.0), image)
    assert np.array_equal(sensing.with_contrast(image, 0.5), [[50, 100], [150, 100]])
    for bad in (0.0, 1.5):
        with pytest.raises(ImageError, match=r"--contrast must be in \(0, 1\]"):
            sensing.with_contrast(image, bad)


@pytest.mark.slow(PROCESS)
def test_sim_at_a_contrast_senses_what_it_senses_on_that_image_written_out(tmp_path):
    from support import run_camo

    from camo_core.algorithm.backgrounds import background

    faint = tmp_path / "faint.png"
    cv2.imwrite(str(faint), sensing.with_contrast(background("leopard"), 0.4))
    runs = {
        "option": ["--pattern", "leopard", "--contrast", "0.4"],
        "file": ["--image", str(faint)],
    }
    summaries = {}
    for name, args in runs.items():
        out = run_camo("sim", *args, "--rho-meas", "0.2", "--out", str(tmp_path / name))
        assert out.returncode == 0, out.stderr
        summaries[name] = json.loads((tmp_path / name / "summary.json").read_text())
    assert summaries["option"]["sensed"] == summaries["file"]["sensed"]
    assert summaries["option"]["final"] == summaries["file"]["final"]
    out = run_camo("sim", "--contrast", "2", "--out", str(tmp_path / "bad"))
    assert (
        out.returncode == 2
        and out.stderr.strip() == "camo: error: --contrast must be in (0, 1] (got 2)"
    )


# ---- what the native decoders say (issue 27) -------------------------------------------------
