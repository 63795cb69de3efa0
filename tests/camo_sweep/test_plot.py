"""`./camo sweep plot`: a metric against an axis with a band that stays above zero, lines by
another axis, a heat map of two, and one-line errors."""

import cv2
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


def test_a_text_axis_of_numbers_and_words_is_ordered_as_numbers_then_words():
    from camo_sweep.plot import _sort_key

    assert sorted(["auto", "100.0", "5.0", None, "30.0"], key=_sort_key) == [
        "5.0", "30.0", "100.0", "auto", None
    ]  # fmt: skip
