"""`camo run`'s option combinations: one table (run_config.RUN_COMBINATIONS) the command line
checks once, each broken rule one line naming both options."""

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from camo_bringup.run_config import RUN_COMBINATIONS, build_parser
from camo_core.exceptions import UsageError

# A value each option of the table takes (flags take none).
VALUES = {
    "--rounds": "2", "--duration": "5", "--image": "a.png", "--video": "a.mp4",
    "--images": "*.png", "--background-topic": "/cam", "--camera": "0", "--then": "desert",
    "--fps": "10", "--period": "2", "--key-file": "k", "--pattern": "forest", "--bridge": "0,0=/x",
    "--max-fps": "5", "--sense-period": "0.5", "--change-window": "5", "--change-threshold": "9",
}  # fmt: skip
FLAGS = sorted({f for r in RUN_COMBINATIONS for f in (r.option, *r.needs, *r.excludes)})


def broken(chosen: set[str]) -> list[tuple[str, str]]:
    """The (option, other) pairs of the table that `chosen` breaks, in the table's order."""
    pairs = []
    for rule in RUN_COMBINATIONS:
        if rule.option not in chosen:
            continue
        if rule.needs and not chosen & set(rule.needs):
            pairs.append((rule.option, rule.needs[0]))
        pairs += [(rule.option, other) for other in rule.excludes if other in chosen]
    return pairs


@settings(max_examples=300, deadline=None)
@given(st.sets(st.sampled_from(FLAGS), max_size=5))
def test_any_set_of_options_parses_or_names_the_first_rule_it_breaks(chosen):
    if {"--image", "--pattern"} <= chosen:
        chosen = chosen - {"--pattern"}  # argparse's own group: not the table's
    argv = [x for flag in sorted(chosen) for x in (flag, VALUES.get(flag)) if x is not None]
    expected = broken(chosen)
    try:
        build_parser().parse_args(argv)
    except UsageError as exc:
        said = str(exc)
        assert expected, said
        first, other = expected[0]
        assert said.startswith(f"{first} ") and other in said and "\n" not in said, said
    else:
        assert not expected, (argv, expected)


def test_an_option_from_a_parameters_file_counts_as_given(tmp_path):
    params = tmp_path / "p.yaml"
    params.write_text("/**:\n  ros__parameters:\n    rounds: 3\n")
    with pytest.raises(UsageError, match="--rounds needs --continuous"):
        build_parser().parse_args(["--params-file", str(params)])
    build_parser().parse_args(["--params-file", str(params), "--continuous"])


@pytest.mark.parametrize(
    "argv, environ, said",
    [
        (["--record", "{tmp}/x", "--out", "{tmp}/x"], {}, "--record {tmp}/x holds --out"),
        (["--record", "{tmp}/x", "--out", "{tmp}/x/r"], {}, "give them apart"),
        (["--no-key"], {"CAMO_ENCRYPT": "1"}, "CAMO_ENCRYPT=1 and --no-key do not go together"),
        (["--discovery-server", "10.0.0.1:11811", "--network", "subnet"], {}, "do not go"),
        (["--image", "{tmp}/figure.png", "--out", "{tmp}", "--force"], {}, "would replace"),
    ],
)
def test_a_run_whose_options_would_lose_or_ignore_something_is_refused_first(
    tmp_path, argv, environ, said
):
    # Each was found to run to its end and then lose the recording, drop the encryption or
    # overwrite its own input.
    import cv2
    import numpy as np

    from camo_bringup.run_config import config_from

    cv2.imwrite(str(tmp_path / "figure.png"), np.full((16, 16), 90, np.uint8))
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    with pytest.raises(UsageError, match=said.replace("{tmp}", str(tmp_path))):
        config_from(build_parser().parse_args(["--rows", "3", "--cols", "3", *argv]), environ)
    assert not (tmp_path / "x").exists() and (tmp_path / "figure.png").exists()


@pytest.mark.parametrize("given", [None, "4"])
def test_the_swarms_processes_load_blas_on_one_thread_however_the_launcher_started(
    tmp_path, given
):
    """Started outside ./camo (`ros2 run`), the launcher still starts its robot processes with
    OpenBLAS on one thread (its pool spins a tenth of a CPU-second in every process as it loads);
    a number the user gives is theirs."""
    from camo_bringup.run_config import config_from

    environ = {"OPENBLAS_NUM_THREADS": given} if given else {}
    argv = ["--rows", "3", "--cols", "3", "--no-key", "--out", str(tmp_path / "out")]
    env = config_from(build_parser().parse_args(argv), environ).env
    assert env["OPENBLAS_NUM_THREADS"] == (given or "1")
