import cv2
import numpy as np
import pytest

from camo_core import sensing
from camo_core.sensing import ImageError


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


def test_image_errors_are_clear(tmp_path):
    with pytest.raises(ImageError, match="not found"):
        sensing.load_image(tmp_path / "missing.png")
    corrupt = tmp_path / "corrupt.png"
    corrupt.write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    with pytest.raises(ImageError, match="cannot read"):
        sensing.load_image(corrupt)
    with pytest.raises(ImageError, match="smaller"):
        sensing.block_means(np.zeros((5, 5)), 8, 8)


def test_colour_alpha_and_grey_files_load(tmp_path):
    bgra = np.zeros((16, 16, 4), np.uint8)
    bgra[..., 2] = 200
    cv2.imwrite(str(tmp_path / "a.png"), bgra)
    assert sensing.load_image(tmp_path / "a.png").shape == (16, 16, 3)
    cv2.imwrite(str(tmp_path / "g.png"), np.full((16, 16), 7, np.uint8))
    assert sensing.load_image(tmp_path / "g.png").shape == (16, 16)
