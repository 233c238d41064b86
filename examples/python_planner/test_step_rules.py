"""mole_runtime.py's step rules give the Rust runtime's answers, and its subscriber receives what
they ask for.

step_rules.json is what processes/runtime/src/step.rs decides (`rule_table`; a Rust test fails
when the file and the rules differ): these tests check the Python functions against every case
of it. Plain unittest, no iceoryx2 needed:

    python3 -m unittest discover -s examples/python_planner -p 'test_*.py'
"""

import json
import os
import sys
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import mole_messages as msg  # noqa: E402
import mole_runtime as rt  # noqa: E402


def load_rules():
    with open(os.path.join(HERE, "step_rules.json"), encoding="utf-8") as f:
        return json.load(f)


class CaseInput:
    """An input of a gate case: its rule, its newest tick and the newest tick seen."""

    topic = "case/input"

    def __init__(self, rule, newest, seen):
        self.rule, self.newest, self.seen = rt.Rule(rule), newest, seen

    def tick(self):
        return self.newest

    def newest_seen(self):
        return max((t for t in (self.newest, self.seen) if t is not None), default=None)


class TheRustRules(unittest.TestCase):
    """Every decision step_rules.json records, made by mole_runtime.py."""

    @classmethod
    def setUpClass(cls):
        cls.rules = load_rules()

    def test_the_table_names_exactly_the_python_rules(self):
        """A rule Rust has and Python lacks (or the reverse) fails here, not in a run."""
        in_table = {case["rule"] for case in self.rules["gate_tick"]}
        self.assertEqual(in_table, {rule.value for rule in rt.Rule})

    def test_gate_tick_counts_every_input_as_rust_does(self):
        """Each rule × newest tick × step k counts as the tick Rust's gate_tick gives."""
        for case in self.rules["gate_tick"]:
            with self.subTest(**case):
                counts_as = rt.gate_tick(rt.Rule(case["rule"]), case["newest"], case["k"])
                self.assertEqual(counts_as, case["counts_as"])

    def test_the_gate_decides_every_step_as_rust_does(self):
        """Each gate case (clock mode, last step, k, inputs) gets Rust's verdict."""
        self.assertTrue(self.rules["gate"], "the table has gate cases")
        for case in self.rules["gate"]:
            with self.subTest(**case):
                gate = rt.Gate(case["mode"] == "lockstep", lambda text, level="INFO": None,
                               case["last"])
                inputs = [CaseInput(i["rule"], i["newest"], i["seen"]) for i in case["inputs"]]
                self.assertEqual(gate.due(case["k"], inputs), case["due"])


class Sample:
    """A received message of a tick, as the iceoryx2 package hands it out."""

    def __init__(self, tick, seq):
        self.message = msg.Grid()
        self.message.header.tick, self.message.header.seq = tick, seq
        self.deleted = False

    def payload(self):
        return self

    @property
    def contents(self):
        return self.message

    def delete(self):
        self.deleted = True


class Queue:
    """A subscriber port whose queue the test fills."""

    def __init__(self):
        self.queue = []

    def send(self, *ticks):
        self.queue += [Sample(t, len(self.queue) + i) for i, t in enumerate(ticks)]

    def receive(self):
        return self.queue.pop(0) if self.queue else None


def subscriber(rule, valid=lambda message: True):
    queue = Queue()
    stats = rt.PortStats("mapping/grid", msg.DIRECTION_SUBSCRIBE)
    return queue, rt.Subscriber("mapping/grid", queue, valid, stats, rule=rule)


def refresh(port, k, lockstep):
    """What Node.step_due receives for the input at step k."""
    through = rt.receive_through(port.rule, k, lockstep)
    if through is not None:
        port.update_through(through)


def handed(port, k, lockstep):
    """The tick of the sample step k hands the algorithm, or None."""
    sample = rt.Step(k, port, lockstep).get(port)
    return None if sample is None else sample.header.tick


class TheReceivingSide(unittest.TestCase):
    """What each rule receives and hands a step (Rust: processes/runtime/tests/step.rs)."""

    def test_lockstep_previous_tick_holds_an_early_sample_back_and_has_none_at_step_0(self):
        queue, grid = subscriber(rt.Rule.PREVIOUS_TICK)
        queue.send(0)
        refresh(grid, 0, lockstep=True)
        self.assertEqual(grid.tick(), None, "step 0 receives no grid")
        grid.update()
        self.assertEqual(handed(grid, 0, True), None, "nor hands one out: no previous step")
        queue.send(1)
        refresh(grid, 1, lockstep=True)
        self.assertEqual(handed(grid, 1, True), 0, "step 1 gets the grid of step 0")
        self.assertEqual(grid.newest_seen(), 1, "the early grid of step 1 is held back")
        refresh(grid, 2, lockstep=True)
        self.assertEqual(handed(grid, 2, True), 1, "and handed to step 2")
        self.assertTrue(queue.queue == [] and grid.pending == [])

    def test_lockstep_same_tick_takes_step_k_and_never_a_later_one(self):
        queue, scan = subscriber(rt.Rule.SAME_TICK)
        queue.send(3, 4)
        refresh(scan, 3, lockstep=True)
        self.assertEqual(handed(scan, 3, True), 3)
        self.assertEqual(scan.newest_seen(), 4)
        refresh(scan, 4, lockstep=True)
        self.assertEqual(handed(scan, 4, True), 4)

    def test_realtime_takes_the_newest_and_a_missed_same_tick_reading_is_none(self):
        queue, scan = subscriber(rt.Rule.SAME_TICK)
        queue.send(5, 6)
        refresh(scan, 6, lockstep=False)
        self.assertEqual(handed(scan, 6, False), 6)
        self.assertEqual(handed(scan, 7, False), None, "never last step's again")
        queue, grid = subscriber(rt.Rule.PREVIOUS_TICK)
        queue.send(0, 1)
        refresh(grid, 0, lockstep=False)
        self.assertEqual(handed(grid, 0, False), 1, "realtime: the newest there is")

    def test_an_older_step_sent_late_or_an_invalid_message_is_dropped_and_counted(self):
        queue, scan = subscriber(rt.Rule.NEWEST, valid=lambda m: m.header.tick != 9)
        queue.send(5, 4, 9)
        scan.update()
        self.assertEqual(scan.tick(), 5, "a hot swap's old publisher may send late")
        self.assertEqual(scan.stats.invalid, 1)


if __name__ == "__main__":
    unittest.main()
