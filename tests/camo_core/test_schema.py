"""A parameter declared once: its command-line option, its checks, its JSON form, its roles and
the summary fields all come from the declaration."""

from __future__ import annotations

import re
from dataclasses import dataclass

import pytest

from camo_core.algorithm.params import CamoParams
from camo_core.algorithm.result import SUMMARY_KEYS
from camo_core.cli.options import Parser, add_options, options_of
from camo_core.exceptions import UsageError
from camo_core.schema import ParameterError, check_fields, declared, from_dict, param, to_dict
from camo_core.schema import values as role_values
from camo_core.swarm.run_setup import ProtocolParams, RunSetup, SetupError


@dataclass(frozen=True)
class Example:
    speed: float = param(1.5, "how fast", low=0.0, high=10.0, unit="m/s", summary=True)
    count: int = param(3, "how many", low=1, high=9)
    mode: str = param("calm", "how", choices=("calm", "wild"))
    steps: int = param(None, "steps; auto: as many as needed", low=0, high=99, keyword="auto")
    hidden: bool = param(False, "set by the program", cli=False)

    def __post_init__(self) -> None:
        if self.steps is None:
            object.__setattr__(self, "steps", 7)
        check_fields(self)


def parser() -> Parser:
    parser = Parser(prog="example")
    add_options(parser, Example)
    return parser


def test_each_declared_parameter_is_an_option_with_its_type_range_and_default():
    args = parser().parse_args(["--speed", "2.5", "--count", "4", "--mode", "wild"])
    assert (args.speed, args.count, args.mode, args.steps) == (2.5, 4, "wild", None)
    assert Example(**options_of(args, Example)) == Example(2.5, 4, "wild", 7)
    defaults = {"speed": 1.5, "count": 3, "mode": "calm"}
    assert options_of(parser().parse_args([]), Example) == defaults
    assert not hasattr(parser().parse_args([]), "hidden")  # not a command-line parameter
    text = parser().format_help()
    assert "how fast; [0, 10] m/s (default: 1.5)" in " ".join(text.split())


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--count", "2.5"], "invalid int value"),
        (["--mode", "fast"], "invalid choice"),
        (["--steps", "many"], "a whole number or auto (got 'many')"),
    ],
)
def test_a_value_the_option_cannot_take_is_a_one_line_usage_error(argv, message):
    with pytest.raises(UsageError, match=re.escape(message)):
        parser().parse_args(argv)


@pytest.mark.parametrize(
    "values, message",
    [
        ({"speed": -1.0}, r"speed must be a number in \[0, 10\] \(got -1.0\)"),
        ({"speed": float("nan")}, "speed must be a number in"),
        ({"count": 0}, r"count must be an integer in 1\.\.9 \(got 0\)"),
        ({"count": True}, "count must be an integer"),
        ({"mode": "fast"}, "mode must be one of calm, wild"),
        ({"hidden": "yes"}, "hidden must be true or false"),
    ],
)
def test_a_value_out_of_its_declared_range_is_a_parameter_error_naming_it(values, message):
    with pytest.raises(ParameterError, match=message):
        Example(**values)


def test_an_integer_where_a_number_is_declared_becomes_that_number():
    assert Example(speed=2).speed == 2.0 and isinstance(Example(speed=2).speed, float)


def test_the_json_form_goes_back_and_forth_and_refuses_unknown_keys():
    example = Example(speed=0.5, steps=12)
    assert from_dict(Example, to_dict(example)) == example
    with pytest.raises(ParameterError, match="setup: unknown parameter 'sped'"):
        from_dict(Example, {"sped": 1.0}, "setup")
    with pytest.raises(ParameterError, match="setup: count must be an integer"):
        from_dict(Example, {"count": "3"}, "setup")


def test_roles_pick_the_parameters_that_have_them():
    assert role_values(Example(speed=2.0), "summary") == {"speed": 2.0}
    assert declared(Example)["steps"].optional and not declared(Example)["count"].optional


def test_summary_json_holds_the_parameters_declared_for_it_first():
    summary_fields = [n for n, d in declared(CamoParams).items() if d.spec.summary]
    assert list(SUMMARY_KEYS[: len(summary_fields)]) == summary_fields
    assert summary_fields == ["rows", "cols", "profile", "seed", "rho_meas", "rho_comm", "scope"]


def test_camo_params_from_options_resolve_auto_and_leave_none_to_the_profile():
    params = CamoParams.from_options(threshold="auto", consensus_steps="auto", rows=16, cols=16)
    assert params.threshold_auto and params.threshold == 50.0
    assert params.consensus_steps == 161  # 35 * 15^2 / 7^2, rounded up
    assert CamoParams.from_options(formation_steps=None, profile="droplet").formation_steps == 20


def test_a_run_setup_is_checked_once_and_keeps_its_json_form():
    setup = RunSetup("r", CamoParams(rows=4, cols=4), tiles=((0, 7), (8, 15)))
    assert setup.discovery_timeout == 60.0 + 0.01 * 16  # the protocol's default, filled in
    again = RunSetup.from_json(setup.to_json(), "r")
    assert again == setup and again.params == setup.params
    with pytest.raises(SetupError, match="not of other"):
        RunSetup.from_json(setup.to_json(), "other")
    with pytest.raises(SetupError, match=r"step_timeout must be a number in \(0, 86400\]"):
        RunSetup.from_dict({**setup.to_dict(), "step_timeout": 0})
    with pytest.raises(SetupError, match="tiles"):
        RunSetup.from_dict({**setup.to_dict(), "tiles": [[0, 16]]})
    assert ProtocolParams(step_timeout=5).step_timeout == 5.0
