"""Robots' reports as a table: what a process sends as one StatusArray, read back and recorded
as the reports one by one would be."""

from types import SimpleNamespace

import numpy as np
import pytest
from support import Bus

from camo_core.algorithm.params import CamoParams
from camo_core.results.record import RoundRecord
from camo_core.swarm.status_rows import RowsError, StatusRows, rows_of_message
from camo_core.swarm.validation import rows_problems


def bus_reports(params: CamoParams, seed: int) -> list:
    grid = np.random.default_rng(seed).uniform(0, 255, (params.rows, params.cols))
    bus = Bus(params, grid, seed=seed)
    bus.run()
    return bus.reports


def as_message(rows: StatusRows) -> SimpleNamespace:
    """What a StatusArray holds once sent and taken: its fields."""
    return SimpleNamespace(**rows.message_fields())


def assert_same_record(a: RoundRecord, b: RoundRecord) -> None:
    for name in ("sensed", "p_trace", "state_trace", "p_latest", "initial", "state"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    for name in ("selected", "phase", "step", "finished", "deadlines", "palette"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert a.given_up == b.given_up


@pytest.mark.parametrize(
    "params",
    [
        CamoParams(rows=3, cols=4, consensus_steps=8, formation_steps=5, seed=1),
        CamoParams(rows=3, cols=3, consensus_steps=6, formation_steps=4, levels=4, seed=2),
        CamoParams(rows=3, cols=3, consensus_steps=6, formation_steps=4, orientation="any"),
    ],
)
def test_a_table_of_reports_records_what_the_reports_one_by_one_do(params):
    reports = bus_reports(params, seed=3)
    one_by_one = RoundRecord(params)
    for report in reports:
        one_by_one.add(report)
    # Tables of 7 reports, as processes send them: a robot may be in one twice.
    tables = RoundRecord(params)
    for k in range(0, len(reports), 7):
        sent = StatusRows.from_reports(reports[k : k + 7])
        tables.add_rows(StatusRows.from_message(as_message(sent)))
    assert_same_record(tables, one_by_one)
    assert tables.finished.all()


def test_a_robot_reported_twice_in_one_table_keeps_its_later_report():
    params = CamoParams(rows=1, cols=2, consensus_steps=4, formation_steps=2)
    first = SimpleNamespace(sender_id=1, phase=2, step=1, sensed=9.0, p=[1, 0, 0], state=0)
    later = SimpleNamespace(sender_id=1, phase=2, step=3, sensed=9.0, p=[0, 1, 0], state=1)
    record = RoundRecord(params)
    record.add_rows(StatusRows.from_reports([first, later]))
    assert record.step[1] == 3 and record.state[1] == 1
    assert record.p_trace[1, 1].tolist() == [1, 0, 0] and record.p_trace[3, 1].tolist() == [
        0,
        1,
        0,
    ]


def test_columns_whose_lengths_disagree_are_not_a_table():
    two = [SimpleNamespace(sender_id=k, phase=1, p=[0, 0, 1], silent=[1, 2]) for k in (0, 1)]
    fields = StatusRows.from_reports(two).message_fields()
    for name, value in (
        ("phase", [1]),
        ("p", [0.0, 0.0, 1.0, 0.0, 1.0]),  # not the same number of values a row
        ("p", []),
        ("p_trace_count", [1, 0]),  # a step of p's width, and no values
        ("silent", [1]),
        ("silent_count", [3, 2]),
    ):
        with pytest.raises(RowsError):
            StatusRows.from_message(SimpleNamespace(**{**fields, name: value}))


def test_p_is_of_any_width_and_a_report_of_another_width_than_the_others_is_refused():
    # A fourth pattern widens p: a table takes any width, the same for every row; a report whose
    # p is of another width is ragged, and the monitor refuses its row.
    wide = [
        SimpleNamespace(sender_id=k, phase=2, p=[0.25] * 4, p_trace=[0.25] * 8) for k in (0, 1)
    ]
    rows = StatusRows.from_message(
        SimpleNamespace(**StatusRows.from_reports(wide).message_fields())
    )
    assert rows.width == 4 and rows.p_trace_count.tolist() == [2, 2]
    odd = SimpleNamespace(sender_id=2, phase=2, p=[0.5, 0.5])
    mixed = StatusRows.from_reports([*wide, odd])
    assert mixed.ragged.tolist() == [False, False, True]
    problems = rows_problems(mixed, CamoParams(rows=2, cols=2))  # the paper's p: 3 wide
    assert all(problems), problems


def test_a_status_of_an_older_camo_reads_as_one_row():
    old = SimpleNamespace(sender_id=4, row=1, col=1, phase=4, step=2, round=1, sensed=3.0)
    old.p, old.pattern, old.state = [0.0, 1.0, 0.0], 1, 1
    rows = rows_of_message(old, cols=3)
    assert len(rows) == 1 and rows.round.tolist() == [1] and not rows.wrong_cell.any()
    assert rows_of_message(old, cols=4).wrong_cell.all()  # (1, 1) is not robot 4's cell there
