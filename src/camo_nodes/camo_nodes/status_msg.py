"""A robot's report as the camo_msgs/RobotStatus its process publishes on /<run>/swarm/status."""

from __future__ import annotations

from camo_core.algorithm.robot_io import Report
from camo_msgs.msg import RobotStatus


def status_msg(report: Report) -> RobotStatus:
    return RobotStatus(
        sender_id=report.sender_id,
        row=report.row,
        col=report.col,
        phase=report.phase,
        step=report.step,
        round=report.round,
        sensed=report.sensed,
        p=list(report.p),
        pattern=report.pattern,
        state=report.state,
        alive=report.alive,
        known_slots=report.known_slots,
        deadlines=report.deadlines,
        silent=list(report.silent),
        p_from=report.p_from,
        p_trace=list(report.p_trace),
        state_from=report.state_from,
        state_trace=list(report.state_trace),
        palette=list(report.palette),
    )
