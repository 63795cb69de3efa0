"""What the monitor keeps of a run's frames (`Backgrounds`): the rounds' frames, and of the rest
no more than a bounded number and size, however long a camera streams."""

import numpy as np

from camo_core.results.record import Backgrounds


def full_hd(_=None) -> np.ndarray:
    return np.zeros((1080, 1920, 3), np.uint8)  # 6.2 MB, pages untouched


def test_a_camera_s_full_hd_frames_are_held_within_a_budget_and_the_rounds_frames_stay():
    # Its 64 newest frames were held whatever their size: 400 MB of a 1080p camera.
    frames = Backgrounds()
    frames.pin(10)  # a round's frame, noticed before it came
    for number in range(300):
        frames.add((number, 0), full_hd, number, f"sha-{number}")
    loose = [n for n in frames if n != 10]
    assert sum(frames[n].nbytes for n in loose) <= frames.budget
    assert loose == list(range(300 - len(loose), 300)) and len(loose) >= frames.least
    assert 10 in frames and frames.digests[10] == "sha-10"
    assert len(frames.digests) == len(frames.times) == len(frames.stamps) == len(frames)
    frames.unpin(10)
    assert 10 not in frames and (10, 0) not in frames.stamps


def test_small_frames_are_held_by_number():
    frames = Backgrounds(keep=8)
    for number in range(50):
        frames.add((number, 0), lambda: np.zeros((4, 4), np.uint8), number)
    assert sorted(frames) == list(range(42, 50))
