"""`./camo errors`: the paper's error analysis as a preset sweep; its CSV and figure come from
the sweep's table."""

import csv
import subprocess
import sys

import cv2
import pytest
from support import COMPUTE, ROOT, bad_value_outcomes, sweep_table, validated, value_options

from camo_sweep import errors as errors_cli
from camo_sweep.errors import CSV_COLUMNS


def errors(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "camo_sweep.errors", *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )


@pytest.mark.slow(COMPUTE)
def test_errors_writes_csv_figure_and_the_table_they_come_from(tmp_path):
    out = errors("--pattern", "forest", "--trials", "4", "--rhos", "0,0.4", "--out", str(tmp_path))
    assert out.returncode == 0, out.stderr
    rows = list(csv.DictReader((tmp_path / "errors.csv").open()))
    assert [r["mode"] for r in rows] == ["measurement"] * 2 + ["communication"] * 2 + ["both"] * 2
    assert tuple(rows[0]) == CSV_COLUMNS
    at_zero = [r for r in rows if float(r["rho"]) == 0.0]
    assert all(float(r["mean_diff"]) == 0.0 and float(r["correct_rate"]) == 1.0 for r in at_zero)
    assert max(float(r["mean_diff"]) for r in rows) > 0
    assert cv2.imread(str(tmp_path / "errors.png")) is not None
    assert "sweep" in out.stderr  # the progress bar
    # The points are the table's: rho 0 is one point shared by the three modes (4 trials),
    # then 4 trials for each mode at 0.4.
    table = sweep_table(tmp_path)
    assert len(table) == 4 + 3 * 4
    both = [t for t in table if t["rho_meas"] == t["rho_comm"] == 0.4]
    mean = sum(t["diff_cells"] for t in both) / len(both)
    assert (
        float(next(r for r in rows if r["mode"] == "both" and r["rho"] == "0.4")["mean_diff"])
        == mean
    )


@pytest.mark.slow(COMPUTE)
def test_errors_with_colours_draws_the_colour_distance_from_the_tables_column(tmp_path):
    from skimage import data

    image = tmp_path / "chelsea.png"
    cv2.imwrite(str(image), cv2.cvtColor(data.chelsea(), cv2.COLOR_RGB2BGR))
    out = errors("--image", str(image), "--colours", "3", "--trials", "2", "--rhos", "0,0.3",
                 "--out", str(tmp_path / "c"))  # fmt: skip
    assert out.returncode == 0, out.stderr
    rows = list(csv.DictReader((tmp_path / "c" / "errors.csv").open()))
    table = sweep_table(tmp_path / "c")
    assert all(t["colour_distance"] > 0 for t in table)
    both = [t for t in table if t["rho_meas"] == t["rho_comm"] == 0.3]
    said = next(r for r in rows if r["mode"] == "both" and r["rho"] == "0.3")
    assert float(said["mean_colour_distance"]) == sum(t["colour_distance"] for t in both) / 2
    # Four panels: the paper's two, the grey distance and the colour distance.
    figure = cv2.imread(str(tmp_path / "c" / "errors.png"))
    plain = errors("--image", str(image), "--trials", "2", "--rhos", "0,0.3",
                   "--out", str(tmp_path / "p"))  # fmt: skip
    assert plain.returncode == 0, plain.stderr
    assert figure.shape[1] > cv2.imread(str(tmp_path / "p" / "errors.png")).shape[1]


@pytest.mark.slow(COMPUTE)
def test_errors_rejects_bad_rhos_and_a_used_folder(tmp_path):
    out = errors("--rhos", "0,2", "--out", str(tmp_path / "a"))
    assert out.returncode == 2 and "probabilities" in out.stderr
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "x").write_text("")
    out = errors("--out", str(tmp_path / "b"))
    assert out.returncode == 2 and "not empty" in out.stderr


@pytest.mark.slow(COMPUTE)
def test_errors_again_in_its_folder_is_the_same_analysis_or_refused(tmp_path):
    base = ["--trials", "2", "--rhos", "0,0.4", "--quiet", "--out", str(tmp_path)]
    assert errors(*base).returncode == 0
    fewer = errors(*base[:1], "1", *base[2:], "--force")
    assert fewer.returncode == 0, fewer.stderr
    rows = list(csv.DictReader((tmp_path / "errors.csv").open()))
    assert {r["trials"] for r in rows} == {"1"}  # this analysis's trials, not the folder's
    other = errors(*base, "--force", "--pattern", "leopard")
    assert other.returncode == 2 and "holds another sweep" in other.stderr
    noisy = errors("--rho-meas", "0.3", "--out", str(tmp_path / "n"))
    assert noisy.returncode == 2 and "give them as --rhos" in noisy.stderr


@pytest.mark.slow(COMPUTE)
def test_at_lower_contrast_measurement_errors_change_the_forests_pattern(tmp_path):
    def measurement_diff(folder, *extra):
        out = errors("--trials", "10", "--rhos", "0.4", "--quiet", "--out", str(folder), *extra)
        assert out.returncode == 0, out.stderr
        rows = list(csv.DictReader((folder / "errors.csv").open()))
        return float(next(r for r in rows if r["mode"] == "measurement")["mean_diff"])

    # The built-in forest's trunks are strong enough that noisy robots change nothing; pulled
    # toward their mean at contrast 0.3 they are as faint as the paper's photograph.
    assert measurement_diff(tmp_path / "full") == 0.0
    assert measurement_diff(tmp_path / "faint", "--contrast", "0.3") > 5.0
    table = sweep_table(tmp_path / "faint")
    assert all(r["sim_args"].startswith("--pattern forest") for r in table)
    assert all("--contrast 0.3" in r["sim_args"] for r in table)  # each row says how to rerun


# ---- every option with bad values (issue 27) -------------------------------------------------


@pytest.mark.parametrize("option", value_options(errors_cli.build_parser()))
def test_every_option_of_errors_with_a_bad_value_is_one_line_and_exit_2(
    option, tmp_path, monkeypatch, capsys
):
    # Only the command line runs: planning the sweep (its first simulation) is replaced.
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(errors_cli, "plan", validated)
    argv = ["--rows", "2", "--cols", "2", "--trials", "1", "--quiet"]
    if option != "--out":
        argv += ["--out", str(tmp_path / "out"), "--force"]
    assert (
        bad_value_outcomes(errors_cli.main, argv, option, capsys, errors_cli.build_parser()) == []
    )
