"""A sweep's trials: axes over ./camo sim's options, ids and seeds that depend on the trial
alone, and one-line errors for a bad sweep."""

import hashlib

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st
from support import PROCESS

from camo_core.exceptions import UsageError
from camo_core.inputs.files import shown
from camo_sweep.spec import SweepSpec, axis_values, build_spec, spec_from_yaml


def test_a_range_includes_its_end_and_keeps_integers_integers():
    assert axis_values("rho_comm", "0:0.5:0.1") == [0.0, 0.1, 0.2, 0.3, 0.4, 0.5]
    assert axis_values("rows", "4:16:4") == [4, 8, 12, 16]
    assert axis_values("pattern", "forest,desert") == ["forest", "desert"]
    assert axis_values("rho_meas", [0, "0.25"]) == [0.0, 0.25]


@pytest.mark.parametrize(
    "name, values, said",
    [
        ("rho_com", "0,0.1", "unknown option or axis 'rho_com'"),
        ("rho_comm", "", "axis rho_comm is empty"),
        ("rho_comm", "0.1,x", "'x' is not a valid value"),
        ("threshold", "30,high", "'high' is not a valid value"),
        ("consensus_steps", "3,x", "'x' is not a valid value"),
        ("pattern", "forest,jungle", "not one of desert, forest, leopard"),
        ("rho_comm", "0.5:0:0.1", "needs FROM <= TO"),
        ("seed", "1,2", "seed is not an axis"),
        ("rho_comm", "0.1,0.1", "repeats a value"),
        ("rho_comm", "0,,0.1", "axis rho_comm has an empty item"),  # not 2 values
        ("rho_comm", "0,0.1,", "axis rho_comm has an empty item"),
        ("rows", "1_0,8", "'1_0' is not a valid value"),
        ("rows", "\uff18,16", "is not a valid value"),  # a full-width 8
        ("rho_comm", "0:0.5:0.1_0", "'0:0.5:0.1_0' is not a valid value"),
        (",", "0,1", "axis ',' has an empty option name"),
        ("rho_comm,", "0,1", "has an empty option name"),
    ],
)
def test_a_bad_axis_is_one_line(name, values, said):
    with pytest.raises(UsageError, match=said):
        build_spec(None, [f"{name}={values}"], [], 1, 0, None)


def test_an_axis_given_twice_is_refused():
    for axes in (
        ["rho_comm=0,0.1", "rho_comm=0.2,0.3"],
        ["rho_comm=0,0.1", "rho_meas,rho_comm=0.2,0.3"],
        ["rho_comm,rho_comm=0,0.1"],
    ):
        with pytest.raises(UsageError, match="axis rho_comm is given twice"):
            build_spec(None, axes, [], 1, 0, None)


def test_an_option_left_at_a_default_of_none_is_not_on_the_command_line():
    blocks = {"blocks": [{"consensus_steps": [5, 20]}, {"rho_comm": [0.1]}]}
    spec = build_spec(blocks, [], [], 1, 0, None)
    commands = sorted(" ".join(t.sim_args()) for t in spec.trial_list())
    assert commands == [
        "--consensus-steps 20 --rho-comm 0.0",
        "--consensus-steps 5 --rho-comm 0.0",
        "--rho-comm 0.1",
    ]


def test_one_image_by_two_spellings_is_one_trial():
    one = build_spec(None, ["image=a.png"], [], 1, 0, None).trial_list()
    two = build_spec(None, ["image=./a.png"], [], 1, 0, None).trial_list()
    assert [t.trial_id for t in one] == [t.trial_id for t in two]


def test_ids_and_seeds_depend_on_the_trial_not_on_its_place():
    one = build_spec(None, ["rho_comm=0,0.1,0.2", "pattern=forest,desert"], [], 3, 7, None)
    other = build_spec(None, ["pattern=desert,forest", "rho_comm=0.2,0.1,0"], [], 3, 7, None)
    first = {t.trial_id: (t.seed, t.options) for t in one.trial_list()}
    second = {t.trial_id: (t.seed, t.options) for t in other.trial_list()}
    assert first == second and len(first) == 18
    assert len({seed for seed, _ in first.values()}) == 18
    # A trial keeps its id and seed when the sweep around it grows.
    more = build_spec(None, ["rho_comm=0,0.1,0.2,0.3", "pattern=forest,desert"], [], 5, 7, None)
    grown = {t.trial_id: (t.seed, t.options) for t in more.trial_list()}
    assert first.items() <= grown.items()


def test_the_seed_comes_from_a_seed_sequence_of_the_root_seed():
    spec = build_spec(None, ["rho_comm=0.1"], [], 2, 11, None)
    seeds = [t.seed for t in spec.trial_list()]
    again = [t.seed for t in build_spec(None, ["rho_comm=0.1"], [], 2, 11, None).trial_list()]
    other_root = [t.seed for t in build_spec(None, ["rho_comm=0.1"], [], 2, 12, None).trial_list()]
    assert seeds == again and not set(seeds) & set(other_root)
    # As docs/sweeps.md gives it: the spawn key is the first 16 bytes of the SHA-256 of the
    # trial's options (canonical JSON) as four little-endian words, then the replicate.
    digest = hashlib.sha256(b'{"rho_comm":0.1}').digest()
    words = [int.from_bytes(digest[k : k + 4], "little") for k in range(0, 16, 4)]
    for replicate, seed in enumerate(seeds):
        sequence = np.random.SeedSequence(11, spawn_key=(*words, replicate))
        assert seed == int(sequence.generate_state(1, np.uint64)[0])


def test_tied_axes_share_values_and_a_point_in_two_blocks_is_one_trial():
    rhos = [0.0, 0.2]
    spec = SweepSpec(
        blocks=[{"rho_meas": rhos}, {"rho_comm": rhos}, {"rho_meas,rho_comm": rhos}],
        options={"pattern": "forest"},
        trials=2,
    )
    assert spec.axis_names() == ["rho_meas", "rho_comm"]
    trials = spec.trial_list()
    points = [(t.options["rho_meas"], t.options["rho_comm"]) for t in trials]
    # (0, 0) is in all three blocks, yet one point; the tied block adds only (0.2, 0.2).
    assert sorted(set(points)) == [(0.0, 0.0), (0.0, 0.2), (0.2, 0.0), (0.2, 0.2)]
    assert len(trials) == 8 and len({t.trial_id for t in trials}) == 8


def test_a_trial_is_a_sim_command_line():
    spec = build_spec(None, ["rho_comm=0.1"], ["rows=4", "pattern=leopard"], 1, 0, None)
    (trial,) = spec.trial_list()
    assert trial.sim_args() == ["--rows", "4", "--pattern", "leopard", "--rho-comm", "0.1"]


def test_an_option_both_fixed_and_swept_or_two_backgrounds_are_refused():
    with pytest.raises(UsageError, match="both an axis and a fixed option"):
        build_spec(None, ["rows=4,8"], ["rows=8"], 1, 0, None)
    with pytest.raises(UsageError, match="--image or --pattern"):
        build_spec(None, ["image=a.png"], ["pattern=forest"], 1, 0, None)
    with pytest.raises(UsageError, match="at least one axis"):
        build_spec(None, [], [], 1, 0, None)


@pytest.mark.parametrize(
    "text, said",
    [
        ("axes: [1, 2\n", r"is not YAML \(line 2\)"),
        ("- a\n- b\n", "a sweep file is a mapping"),
        ("axis:\n  rho_comm: 0,0.1\n", "unknown key 'axis'"),
        ("axes: 3\n", "axes must be a mapping"),
    ],
)
def test_a_bad_sweep_file_is_one_line(tmp_path, text, said):
    path = tmp_path / "sweep.yaml"
    path.write_text(text)
    with pytest.raises(UsageError, match=said):
        spec_from_yaml(path)


@pytest.mark.parametrize(
    ("text", "said"),
    [
        ("axes: {formation_steps: 1:5:1}\n", "(line 1): '1:5:1' is a base-60 number"),
        ("axes:\n  rho_comm: [0, 0.1]\n  rho_comm: [0.2]\n", "the key 'rho_comm' is given twice"),
        ("seed: " + "9" * 5000 + "\naxes: {rows: [4]}\n", "an integer of 5000 digits"),
        ("axes: {rows: [4]}\n---\naxes: {rows: [8]}\n", "more than one document"),
        ("options: {image: !!binary AAAA}\naxes: {rows: [4]}\n", "the tag !!binary"),
        ("axes: {rows: 0x4}\n", "'0x4' is a number in another base"),
    ],
)
def test_a_sweep_file_read_otherwise_by_yaml_1_1_is_one_line_not_a_run(tmp_path, text, said):
    path = tmp_path / "sweep.yaml"
    path.write_text(text)
    with pytest.raises(UsageError) as caught:
        build_spec(spec_from_yaml(path), [], [], None, None, None)
    assert said in str(caught.value) and "\n" not in str(caught.value)
    # The path as messages show one (longer than 80 characters, as in a worker's tmp_path:
    # shortened in the middle).
    assert str(caught.value).startswith(f"the sweep file {shown(path)} is not YAML")


@pytest.mark.slow(PROCESS)
def test_a_base_60_axis_is_refused_by_camo_sweep_with_exit_2(tmp_path):
    from support import sweep

    path = tmp_path / "sweep.yaml"
    path.write_text("axes: {formation_steps: 1:5:1}\n")
    out = sweep(str(path), "--out", str(tmp_path / "out"))
    assert out.returncode == 2 and "'1:5:1' is a base-60 number" in out.stderr, out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and not (tmp_path / "out").exists()


def test_a_sweep_file_and_the_command_line_combine(tmp_path):
    path = tmp_path / "sweep.yaml"
    path.write_text(
        "seed: 3\ntrials: 4\noptions:\n  rows: 4\naxes:\n  rho_comm: 0:0.2:0.1\n"
        "  pattern: [forest, desert]\n"
    )
    spec = build_spec(spec_from_yaml(path), ["threshold=40,60"], [], 2, None, None)
    assert (spec.seed, spec.trials, spec.options) == (3, 2, {"rows": 4})
    assert spec.axis_names() == ["rho_comm", "pattern", "threshold"]
    assert spec.count() == 3 * 2 * 2 * 2


@pytest.mark.slow(PROCESS)
def test_millisecond_trials_are_batched_into_tasks_of_about_batch_s(tmp_path):
    from camo_sweep.engines import InProcess
    from camo_sweep.sweep import run_sweep

    class Counting(InProcess):
        def __init__(self) -> None:
            self.sizes: list[int] = []

        def run(self, tasks, **kwargs):
            for function, args in tasks:
                self.sizes.append(len(args[0]))
                yield function(*args)

    spec = build_spec(None, ["rho_comm=0:0.5:0.1"], [], 100, 0, None)
    engine = Counting()
    report = run_sweep(spec, tmp_path, engine, batch_s=0.2, progress=False)
    assert report.ran == 600 and sum(engine.sizes) == 600
    # An 8x8 trial takes about a millisecond: tens of trials a task, not one (the kernels'
    # compilation, on a first run, must not be taken for a trial's cost). A trial's cost is
    # timed once: on a busy machine (the other tests of a parallel session) it can take 20 ms,
    # and a task of 0.2 s still holds 10.
    assert 10 <= max(engine.sizes) <= 600 and len(engine.sizes) < 60


# ---- structured bad sweep files (issue 27) ---------------------------------------------------

VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**30), 10**30),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(["", "nan", "inf", "-1", "1e300", "0:1:0", "1:0:1", "0:1e9:1e-9", "a,b"]),
    st.sampled_from(["0.1,0.1", "x" * 300, "hex", "paper", "forest", "auto", "8"]),
    st.lists(st.one_of(st.integers(-2, 10), st.floats(0, 1), st.none(), st.text(max_size=3))),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)
NAMES = st.one_of(
    st.sampled_from(
        ["rows", "cols", "rho_comm", "rho_meas,rho_comm", "threshold", "pattern", "image"]
        + ["seed", "layout", "sensed", "contrast", "force", "out", "bogus", "", "rows,rows"]
        + ["after"]
    ),
    st.integers(0, 2),
    st.none(),
    st.booleans(),
)
SWEEP_FILES = st.one_of(
    st.fixed_dictionaries(
        {},
        optional={
            "axes": st.one_of(st.dictionaries(NAMES, VALUES, max_size=2), VALUES),
            "options": st.one_of(st.dictionaries(NAMES, VALUES, max_size=2), VALUES),
            "trials": VALUES,
            "seed": VALUES,
            "driver": VALUES,
            "blocks": st.one_of(st.lists(st.dictionaries(NAMES, VALUES, max_size=2)), VALUES),
            "slurm": VALUES,
            "bogus": VALUES,
        },
    ),
    VALUES,
)


@given(tree=SWEEP_FILES)
@settings(max_examples=120, deadline=None)
def test_a_sweep_file_of_wrong_types_and_ranges_is_one_line_or_a_spec(tmp_path_factory, tree):
    path = tmp_path_factory.mktemp("sweep") / "s.yaml"
    path.write_text(yaml.safe_dump(tree, sort_keys=False))
    try:
        spec = build_spec(spec_from_yaml(path), [], [], None, None, None)
    except UsageError as exc:
        assert str(exc) and "\n" not in str(exc)
    else:
        assert 1 <= spec.count() <= 10_000_000


@pytest.mark.parametrize(
    "content, said",
    [
        (b"axes:\n  1: [1, 2]\n", "axes: 1 is not an option name"),
        (b"blocks:\n  - {null: [1]}\n", "blocks: nothing is not an option name"),
        (b"\xff\xfe\x00binary", "is not UTF-8 text"),
        (b"1: 2\nbogus: 3\n", "unknown key 1"),
    ],
)
def test_a_sweep_file_with_keys_that_are_not_names_or_not_text_is_one_line(
    tmp_path, content, said
):
    path = tmp_path / "sweep.yaml"
    path.write_bytes(content)
    with pytest.raises(UsageError, match=said):
        build_spec(spec_from_yaml(path), [], [], None, None, None)


@pytest.mark.parametrize("name, said", [("", "empty"), ("x" * 5000, "too long"), (".", "folder")])
def test_a_sweep_file_path_that_is_no_file_is_one_line(tmp_path, monkeypatch, name, said):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(UsageError, match=said):
        spec_from_yaml(name)


@pytest.mark.parametrize(
    "args, said",
    [
        (
            ["--axis", "rho_comm=0:1:0.01", "--trials", "2", "--max-trials", "100"],
            "the sweep has 202 trials, more than --max-trials 100: fewer values or replicates",
        ),
        (
            ["--axis", "rows=1:4096:1", "--axis", "cols=1:4096:1"],
            "the sweep has 16,777,216 trials, more than the 10,000,000 a sweep may have",
        ),
        (["--axis", "rho_comm=0.1", "--trials", str(10**30)], "the sweep has 1,000,000,000,000"),
        (["--axis", "rho_comm=0.1", "--max-trials", "0"], "--max-trials must be in 1..10000000"),
    ],
)
def test_a_sweep_of_too_many_trials_is_one_line_before_anything(tmp_path, capsys, args, said):
    # Counted from the axes' lengths: no trial is listed, no folder made.
    from camo_sweep import cli

    assert cli.main([*args, "--workers", "1", "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err
    assert said in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "s").exists()


def test_a_sweep_says_how_many_trials_it_has_and_runs_before_it_starts(tmp_path, capsys):
    from camo_sweep import cli

    argv = ["--axis", "rho_comm=0,0.5", "--set", "rows=3", "--set", "cols=3", "--trials", "2"]
    argv += ["--workers", "1", "--out", str(tmp_path / "s")]
    assert cli.main(argv) == 0
    assert "camo sweep: 4 trials, 4 to run\n" in capsys.readouterr().err
    assert cli.main([*argv[:-6], "--trials", "3", *argv[-4:]]) == 0  # one replicate more
    assert "camo sweep: 6 trials (4 in the table already), 2 to run\n" in capsys.readouterr().err


def test_more_local_workers_than_the_machine_can_run_is_one_line(tmp_path, capsys):
    # A thousand on two cores started for minutes, then broke in multiprocessing and hung.
    import os

    from camo_sweep import cli

    argv = ["--axis", "rho_comm=0,0.5", "--set", "rows=3", "--set", "cols=3"]
    limit = min(1024, 8 * (os.cpu_count() or 1))
    for workers in (limit + 1, 0):
        out = tmp_path / f"s{workers}"
        assert cli.main([*argv, "--workers", str(workers), "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [
            f"camo sweep: error: --workers must be in 1..{limit} on this machine "
            f"({os.cpu_count()} cores, 8 a core at most; got {workers}): more go to a "
            "cluster, --scheduler or --slurm"
        ]
        assert not out.exists()


def test_a_previous_round_is_no_axis_of_a_sweep(tmp_path, capsys):
    # --after's value was passed over and every trial recorded "ok" as a first round.
    from camo_sweep import cli

    argv = ["--axis", "after=/a,/b", "--workers", "1", "--out", str(tmp_path / "s")]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown option or axis 'after'" in err[0], err


def test_a_sweep_listed_slowly_says_so_before_it_lists(tmp_path, capsys, monkeypatch):
    # 10^7 trials (the most a sweep may have) took minutes and 3 GB before a word.
    from camo_sweep import cli

    monkeypatch.setattr(cli, "LISTED_SLOWLY", 4)
    argv = ["--axis", "rho_comm=0,0.5", "--set", "rows=3", "--set", "cols=3", "--trials", "2"]
    assert cli.main([*argv, "--workers", "1", "--out", str(tmp_path / "s")]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err[:2] == [
        "camo sweep: listing 4 trials before it starts",
        "camo sweep: 4 trials, 4 to run",
    ]
