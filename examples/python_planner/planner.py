#!/usr/bin/env python3
"""mole's planning role in Python: a wall-avoiding wanderer.

world/map once, then localization/pose (the trigger), sensing/scan (step k) and mapping/grid
(step k−1, unused: awaited in lockstep so that mapping keeps up, as the Rust planner does) →
planning/cmd and planning/status, through iceoryx2's Python package and the ctypes layouts of
mole_messages.py (generated from the Rust types). Run it in the place of the Rust planner, from
the repository's root:

    mole up --swap planning="python3 examples/python_planner/planner.py"
"""

import math
import random
import sys

import mole_messages as msg
from mole_runtime import BadInput, Node, Rule, common_args


class Wanderer:
    """Drives ahead, its heading wandering a little. When the scan shows something in the
    corridor the robot is about to sweep, it turns on the spot toward the more open side until
    that corridor is clear by a wider margin (the hysteresis keeps it from chattering)."""

    def __init__(self, robot, seed):
        self.radius = robot.radius
        self.speed, self.turn_rate = 0.6 * robot.max_speed, 0.7 * robot.max_omega
        self.stop_at, self.clear_at = robot.radius + 0.3, robot.radius + 0.6
        self.turning, self.drift = 0, 0.0
        self.random = random.Random(seed)
        self.last = 0.0, 0.0, msg.MODE_EXPLORE

    def step(self, scan):
        """(v, ω, mode) for one step, from a scan in the robot frame; without a scan of this
        step (realtime: it missed the pose), the command of the step before."""
        if scan is None:
            return self.last
        self.last = self.decide(scan)
        return self.last

    def decide(self, scan):
        """(v, ω, mode) from a scan in the robot frame."""
        ahead, left, right = math.inf, 0.0, 0.0
        for i, r in enumerate(scan.ranges[: scan.n_beams]):
            a = scan.angle_min + i * scan.angle_increment
            if math.cos(a) > 0 and abs(r * math.sin(a)) < self.radius + 0.05:
                ahead = min(ahead, r * math.cos(a))
            if math.sin(a) > 0:
                left += r
            else:
                right += r
        if self.turning and ahead > self.clear_at:
            self.turning = 0
        elif not self.turning and ahead < self.stop_at:
            self.turning = 1 if left >= right else -1
        if self.turning:
            return 0.0, self.turning * self.turn_rate, msg.MODE_BOUNCE_BACK
        self.drift = min(1.0, max(-1.0, 0.95 * self.drift + self.random.gauss(0.0, 0.15)))
        slow_down = min(1.0, (ahead - self.stop_at) / (self.clear_at - self.stop_at))
        v = self.speed * max(0.3, slow_down)
        return v, 0.3 * self.turn_rate * self.drift, msg.MODE_EXPLORE


def finite(*values):
    return all(math.isfinite(v) for v in values)


def valid_map(world):
    robot = world.robot
    return robot.radius > 0 and finite(robot.radius, robot.max_speed, robot.max_omega)


def valid_scan(scan):
    n = scan.n_beams
    return (n <= msg.MAX_BEAMS and finite(scan.angle_min, scan.angle_increment)
            and all(math.isfinite(r) and r >= 0 for r in scan.ranges[:n]))


def run():
    namespace, lockstep, seed = common_args()
    node = Node("planning", namespace, lockstep, seed)
    node.trigger(msg.LOCALIZATION_POSE, lambda p: finite(p.x, p.y, p.theta))
    scan_in = node.input(msg.SENSING_SCAN, Rule.SAME_TICK, valid_scan)
    node.input(msg.MAPPING_GRID, Rule.PREVIOUS_TICK, lambda g: g.width * g.height <= len(g.cells))
    cmd_out = node.publisher(msg.PLANNING_CMD)
    status_out = node.publisher(msg.PLANNING_STATUS)

    def act(wanderer, step):
        v, omega, mode = wanderer.step(step.get(scan_in))

        def fill_cmd(cmd):
            cmd.v, cmd.omega, cmd.mode = v, omega, mode

        def fill_status(status):
            # The mode just commanded. No goal, no frontier, no path: the sample comes zeroed,
            # so flags, goal, frontier, bounces and n_path are already 0.
            status.mode = mode

        # origin_ns travels on: the world measures the loop latency from it. The status
        # follows the command, as with the Rust planner.
        cmd_out.publish(step.tick, step.origin_ns, fill_cmd)
        status_out.publish(step.tick, step.origin_ns, fill_status)

    node.run(valid_map, lambda start: Wanderer(start.map.robot, start.seed), act)


def main():
    try:
        run()
    except BadInput as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
