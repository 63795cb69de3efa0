"""A node's ROS parameters come from the same declarations as the command line: the `-p`
arguments the launcher writes for a run's parameters are read back by a node as those very
parameters."""

from __future__ import annotations

import pytest
import rclpy
from rclpy.node import Node
from support import domain

from camo_core.algorithm.params import CamoParams
from camo_core.schema import ParameterError
from camo_core.swarm.run_setup import ProtocolParams
from camo_nodes.robot_node import ROBOT_PARAMETERS, RobotCell, robot_setup
from camo_nodes.topics.parameters import (
    JoinParams,
    declarations,
    node_parameters,
    parameters_help,
    ros_arguments,
)
from camo_nodes.topics.startup import LEAN_NODE


def read_back(arguments: list[str], *classes: type) -> dict:
    """What a node started with these ROS arguments declares."""
    context = rclpy.Context()
    rclpy.init(args=["prog", "--ros-args", *arguments], context=context, domain_id=domain())
    try:
        node = Node("reader", context=context, **LEAN_NODE)
        try:
            return node_parameters(node, *classes)
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def test_a_runs_parameters_written_as_ros_arguments_are_read_back_by_a_robot_node():
    params = CamoParams(
        rows=5,
        cols=7,
        profile="droplet",
        seed=2**63 + 5,
        rho_comm=0.125,
        threshold=12.5,
        threshold_auto=True,
        orientation="any",
        levels=3,
        layout="jitter:0.25",
        consensus_steps=0,
        w2_mottled=-0.5,
    )
    protocol = ProtocolParams(step_timeout=4.0, discovery_timeout=9.5)
    arguments = [
        *ros_arguments(params),
        *ros_arguments(protocol),
        *ros_arguments(RobotCell(4, 6)),
        *ros_arguments(JoinParams("run_x")),
    ]
    values = read_back(arguments, *ROBOT_PARAMETERS)
    robot = robot_setup(values)
    assert (robot.params, robot.protocol, robot.cell) == (params, protocol, RobotCell(4, 6))
    assert values["run_id"] == "run_x"


def test_a_parameter_left_out_is_its_declared_default_and_none_where_the_dataclass_fills_it():
    values = read_back([], *ROBOT_PARAMETERS)
    assert values["consensus_steps"] is None and values["discovery_timeout"] is None
    robot = robot_setup(values)
    assert robot.params == CamoParams() and robot.protocol.discovery_timeout == 60.0 + 0.64


@pytest.mark.parametrize(
    "argument, message",
    [
        ("rows:=eight", r"rows must be an integer \(got 'eight'\)"),
        ("rho_comm:=true", r"rho_comm must be a number \(got True\)"),
        ("colour:=3", "reader has no parameter colour"),
    ],
)
def test_a_wrong_kind_or_an_unknown_parameter_is_one_line(argument, message):
    with pytest.raises(ParameterError, match=message):
        read_back(["-p", argument], *ROBOT_PARAMETERS)


def test_a_value_out_of_range_is_said_by_the_dataclass_it_goes_to():
    with pytest.raises(ParameterError, match=r"rho_comm must be a number in \[0, 1\]"):
        robot_setup(read_back(["-p", "rho_comm:=1.5"], *ROBOT_PARAMETERS))


def test_every_declared_parameter_of_a_robot_is_listed_in_its_help_with_its_default():
    lines = parameters_help(*ROBOT_PARAMETERS)
    assert [line.split(" ")[0] for line in lines] == list(declarations(*ROBOT_PARAMETERS))
    steps = next(line for line in lines if line.startswith("consensus_steps"))
    assert steps.startswith("consensus_steps (-1: 35 paper, 10 droplet)")
    assert read_back([], ProtocolParams)["step_timeout"] == ProtocolParams().step_timeout
