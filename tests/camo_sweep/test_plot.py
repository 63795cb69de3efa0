"""`./camo sweep plot`: a metric against an axis with a band that stays above zero, lines by
another axis, a heat map of two, and one-line errors."""

import cv2
import numpy as np
import pytest
from support import PROCESS, sweep


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    out = tmp_path_factory.mktemp("plot") / "s"
    done = sweep(
        "--axis",
        "rho_comm=0,0.3,0.5",
        "--axis",
        "threshold=30,50",
        "--trials",
        "5",
        "--workers",
        "1",
        "--quiet",
        "--out",
        str(out),
    )
    assert done.returncode == 0, done.stderr
    return out


@pytest.mark.slow(PROCESS)
@pytest.mark.parametrize(
    "extra, name",
    [
        ([], "diff_cells_rho_comm.png"),
        (["--y", "correct", "--by", "threshold"], "correct_rho_comm_by_threshold.png"),
        (["--heat", "threshold"], "diff_cells_rho_comm_heat_threshold.png"),
    ],
)
def test_plot_draws_a_picture_of_the_table(swept, extra, name):
    done = sweep("plot", str(swept), "--x", "rho_comm", *extra)
    assert done.returncode == 0, done.stderr
    image = cv2.imread(str(swept / name))
    assert image is not None and image.shape[1] > 500


def test_the_band_of_a_count_never_goes_below_zero(swept):
    import matplotlib.pyplot as plt

    from camo_sweep.plot import plot

    captured = {}
    real = plt.Figure.savefig

    def keep(fig, *args, **kwargs):
        captured["fig"] = fig
        return real(fig, *args, **kwargs)

    plt.Figure.savefig = keep
    try:
        plot(swept, "rho_comm", "diff_cells", None, None, swept / "band.png")
    finally:
        plt.Figure.savefig = real
    ax = captured["fig"].axes[0]
    assert ax.get_ylim()[0] == 0
    assert all(p.vertices[:, 1].min() >= 0 for c in ax.collections for p in c.get_paths())


@pytest.mark.slow(PROCESS)
def test_an_axis_the_sweep_does_not_have_is_one_line(swept):
    done = sweep("plot", str(swept), "--x", "rows")
    assert done.returncode == 2 and "'rows' is not an axis of this sweep" in done.stderr
    assert "rho_comm, threshold" in done.stderr


@pytest.mark.parametrize("theirs", [b"mine", b"\x89PNG\r\n\x1a\n broken", "a real png"])
def test_a_file_camo_did_not_write_is_never_replaced_and_its_own_is(
    swept, tmp_path, capsys, theirs
):
    from camo_sweep import cli

    path = tmp_path / "figure.png"
    if theirs == "a real png":  # another program's PNG: a picture, but not camo's
        cv2.imwrite(str(path), np.zeros((8, 8, 3), np.uint8))
    else:
        path.write_bytes(theirs)
    before = path.read_bytes()
    argv = ["plot", str(swept), "--x", "rho_comm", "--out", str(path)]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert "camo did not write it" in err and len(err.strip().splitlines()) == 1, err
    assert path.read_bytes() == before
    own = tmp_path / "own.png"
    assert cli.main([*argv[:-1], str(own)]) == 0 and cli.main([*argv[:-1], str(own)]) == 0
    assert cv2.imread(str(own)) is not None  # drawn, then drawn again over its own picture


def test_a_text_axis_of_numbers_and_words_is_ordered_as_numbers_then_words():
    from camo_sweep.plot import _sort_key

    assert sorted(["auto", "100.0", "5.0", None, "30.0"], key=_sort_key) == [
        "5.0", "30.0", "100.0", "auto", None
    ]  # fmt: skip
