"""run.gif: the simulator and the swarm feed the same frames, and the GIF shows the round."""

import numpy as np
import pytest
from support import PROCESS, Bus, run_camo

from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.simulator import simulate
from camo_core.results.record import RoundRecord
from camo_core.results.snapshots import MAX_FRAMES, Snapshots, shown_steps


def gif_frames(path) -> list[bytes]:
    from PIL import Image

    with Image.open(path) as image:
        frames = []
        for k in range(image.n_frames):
            image.seek(k)
            frames.append(image.convert("RGB").tobytes())
    return frames


@pytest.mark.slow(PROCESS)
def test_sim_writes_a_small_animation_that_changes_over_many_frames(tmp_path):
    out = run_camo("sim", "--rho-meas", "0.1", "--rho-comm", "0.1", "--out", str(tmp_path))
    assert out.returncode == 0, out.stderr
    gif = tmp_path / "run.gif"
    assert "run.gif" in out.stdout and gif.stat().st_size < 2 * 1024 * 1024
    frames = gif_frames(gif)
    assert len(frames) == 35 + 10 + 2 + 1  # every step, both starts and the chosen patterns
    assert len(set(frames)) >= 10


def test_a_long_round_is_sampled_with_its_first_and_last_steps():
    consensus, formation = shown_steps(1000, 300)
    assert len(consensus) + len(formation) == MAX_FRAMES
    assert consensus[0] == 0 and formation[-1] == 300
    assert consensus == sorted(consensus) and formation == sorted(formation)
    assert shown_steps(3, 2) == ([0, 1, 2, 3], [0, 1, 2])


def test_the_swarms_frames_equal_the_simulators():
    params = CamoParams(rows=3, cols=4, consensus_steps=12, formation_steps=6, seed=3)
    grid = np.random.default_rng(1).uniform(0, 255, (params.rows, params.cols))
    bus = Bus(params, grid, seed=1)
    bus.run()
    record = RoundRecord(params)
    for report in bus.reports:
        record.add(report)
    simulated = Snapshots(params)
    simulate(params, grid, observe=simulated)
    swarm = Snapshots.of_record(record)
    assert [c for c, _ in swarm.shown()] == [c for c, _ in simulated.shown()]
    assert len(swarm.shown()) == 12 + 6 + 2 + 1  # the steps, both starts, the choice
    for (caption, a), (_, b) in zip(swarm.shown(), simulated.shown(), strict=True):
        assert np.array_equal(a, b), caption


def test_a_large_swarm_is_shown_by_every_kth_robot():
    params = CamoParams(rows=600, cols=300, consensus_steps=2, formation_steps=1)
    snapshots = Snapshots(params)
    state = np.arange(params.count).reshape(600, 300) % 2
    snapshots("formation", 1, state)
    (_, rgb), *_ = snapshots.shown()
    assert snapshots.stride == 3 and rgb.shape == (200, 100, 3)
    assert np.array_equal(rgb[..., 0], np.where(state[::3, ::3] == 1, 0.0, 1.0))


def test_a_frame_given_as_bytes_draws_the_pixels_its_floats_would():
    # run.gif's frames are handed to matplotlib as bytes (quicker to draw): the picture must
    # be the one matplotlib makes of the floats, a panel smaller and larger than the frame.
    import warnings

    import matplotlib.pyplot as plt

    from camo_core.results.animation import _rgba_bytes

    rgb = np.random.default_rng(5).random((256, 256, 3))
    rgb[:8] = [0.0, 1.0, 0.5]  # the ends of the range and a half
    rgb[8:12] = [-0.25, 1.5, 1.0 + 1e-9]  # beyond them: matplotlib clips floats
    for inches in (3.2, 8.0):
        drawn = []
        for frame in (rgb, _rgba_bytes(rgb)):
            fig, ax = plt.subplots(figsize=(inches, inches), dpi=80)
            with warnings.catch_warnings():  # what matplotlib says of the clipped floats
                warnings.simplefilter("ignore", UserWarning)
                ax.imshow(frame, interpolation="nearest")
            fig.canvas.draw()
            drawn.append(np.asarray(fig.canvas.buffer_rgba()).copy())
            plt.close(fig)
        assert np.array_equal(drawn[0], drawn[1])
