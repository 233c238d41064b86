"""The stack's conventions for a Python process: what processes/runtime does for the Rust ones.

- The node is `mole/<namespace>/<role>`; a topic is the publish-subscribe service
  `mole/<namespace>/<topic>` plus an event service of the same name, both opened with the
  settings the runtime gives them (else iceoryx2 refuses the open as incompatible).
- A publisher loans a sample, writes it in place, stamps the header (seq, tick, stamp_ns =
  CLOCK_MONOTONIC, origin_ns), sends it and notifies the event. Lockstep never drops: a full
  subscriber makes the publisher wait; realtime drops the oldest sample.
- A subscriber drains its queue, drops and counts what fails validation, keeps the newest
  (by tick), and holds back a sample newer than the step asked for.
- The step loop (runtime/src/step.rs): a process declares its trigger and its inputs, each with
  a `Rule`; `Node.run` waits for `world/map`, decides when a step is due in either clock mode
  (`Gate`, `gate_tick`), receives what each rule needs (`receive_through`) and hands the
  algorithm what each rule allows (`hands_out`). step_rules.json holds the Rust rules'
  decisions; test_step_rules.py checks these functions against it.
- Statistics go out on stack/stats once a second; the first one tells the launcher "ready".
- SIGINT/SIGTERM end the wait: iceoryx2's WaitSet handles them here.
"""

import ctypes
import enum
import os
import resource
import sys
import time
from typing import NamedTuple

import mole_messages as msg

try:
    import iceoryx2 as iox2
except ImportError:  # the step rules need no IPC; a Node refuses to start without it
    iox2 = None

STATS_PERIOD_NS = 1_000_000_000


class BadInput(Exception):
    """Input a process refuses: exit code 2, which no restart policy retries."""


class Rule(enum.Enum):
    """Which of an input's samples a step uses, and whether a lockstep step waits for it."""

    SAME_TICK = "same_tick"
    """The sample of step k: lockstep waits for it; realtime uses it only if it carries k."""
    PREVIOUS_TICK = "previous_tick"
    """The sample of step k−1: lockstep waits for it and never hands out k even if it came
    early; step 0 has none. Realtime: the newest there is."""
    NEWEST = "newest"
    """The newest sample there is, whatever its tick; never waited for."""


ANY_TICK = 2**64 - 1
"""`receive_through` bound that receives everything: the newest sample."""


def gate_tick(rule, newest, k):
    """The tick an input by `rule` whose newest sample is at `newest` counts as in the lockstep
    gate of step k (None: not there yet); a step is due when every input counts as k."""
    if rule is Rule.SAME_TICK:
        return newest
    if rule is Rule.PREVIOUS_TICK:
        if k == 0:
            return 0  # step 0 has no previous step
        return None if newest is None else newest + 1
    return k


def receive_through(rule, k, lockstep):
    """The highest tick an input by `rule` receives up to for step k (None: receive nothing)."""
    if not lockstep or rule is Rule.NEWEST:
        return ANY_TICK
    if rule is Rule.SAME_TICK:
        return k
    return None if k == 0 else k - 1


def hands_out(rule, tick, k, lockstep):
    """Whether step k hands the algorithm an input's newest sample, at `tick` (None: none)."""
    if tick is None:
        return False
    if rule is Rule.SAME_TICK:
        return tick == k
    if rule is Rule.PREVIOUS_TICK and lockstep:
        return k > 0
    return True


INCOMPLETE_WARNING_NS = 2_000_000_000
"""Lockstep: a step held this long with its trigger but not its other inputs is reported."""


class Gate:
    """Decides whether the trigger's tick k is a step to handle now: realtime, whenever k is
    new; lockstep, when k is new and every input counts as k (`gate_tick`). A lockstep step
    whose SAME_TICK reading was sent before this process listened (it joined mid-run) is
    skipped once a later reading is in. `log(text, level)` reports both."""

    def __init__(self, lockstep, log, last=None):
        self.lockstep, self.log, self.last = lockstep, log, last
        self.skipped, self.incomplete, self.warned = 0, None, False

    def due(self, k, inputs):
        """"step", "skip" (marked handled: go on with the next) or "not yet", for the trigger
        at k and the other `inputs` (each with rule, tick(), newest_seen() and topic)."""
        if self.last is not None and k <= self.last:
            return "not yet"
        if not self.lockstep:
            self.last = k
            return "step"
        if all(gate_tick(i.rule, i.tick(), k) == k for i in inputs):
            if self.skipped:
                self.log(f"joined the run at step {k}: skipped the {self.skipped} steps whose "
                         "readings came before us")
            self.skipped, self.incomplete, self.last = 0, None, k
            return "step"
        if any(i.rule is Rule.SAME_TICK and (seen := i.newest_seen()) is not None and seen > k
               for i in inputs):
            self.skipped += 1
            self.last = k
            return "skip"
        if self.incomplete is None or self.incomplete[0] != k:
            self.incomplete = (k, now_ns())
        if now_ns() - self.incomplete[1] > INCOMPLETE_WARNING_NS and not self.warned:
            self.warned = True
            missing = [i.topic for i in inputs if gate_tick(i.rule, i.tick(), k) != k]
            self.log(f"lockstep: step {k} has its trigger but not all its inputs: {missing}",
                     "WARN")
        return "not yet"


class Start(NamedTuple):
    """What `init` gets once the world's map is in."""

    map: object
    seed: int
    lockstep: bool


class Step:
    """One step: its tick k, the trigger's origin_ns, and the inputs as their rules give them."""

    def __init__(self, tick, trigger, lockstep):
        self.tick, self.lockstep, self._trigger = tick, lockstep, trigger

    @property
    def origin_ns(self):
        """The trigger's origin_ns: the stamp of the ground truth this step derives from, to
        pass on with every output (the world measures the loop latency from it)."""
        return self._trigger.latest().header.origin_ns

    def trigger(self):
        """The trigger's sample of this step."""
        return self._trigger.latest()

    def get(self, port):
        """The input's sample for this step by its rule, or None."""
        if hands_out(port.rule, port.tick(), self.tick, self.lockstep):
            return port.latest()
        return None


def now_ns():
    """CLOCK_MONOTONIC (ns): the clock of every stamp_ns and origin_ns."""
    return time.clock_gettime_ns(time.CLOCK_MONOTONIC)


def common_args():
    """(namespace, lockstep, seed or None) from the environment the launcher sets."""
    namespace = os.environ.get("MOLE_NAMESPACE", "robot0")
    mode = os.environ.get("MOLE_MODE", "realtime")
    if mode not in ("realtime", "lockstep"):
        raise BadInput(f"MOLE_MODE: unknown clock mode `{mode}`, expected realtime or lockstep")
    seed = os.environ.get("MOLE_SEED")
    if seed is not None and not seed.isdigit():
        raise BadInput(f"MOLE_SEED: expected an unsigned integer, found `{seed}`")
    return namespace, mode == "lockstep", None if seed is None else int(seed)


class PortStats:
    """One port's counters, as the runtime reports them in a TopicStats slot."""

    def __init__(self, topic, direction):
        self.topic, self.direction = topic, direction
        self.count = self.dropped = self.invalid = self.window_count = 0
        self.latencies_us = []

    def counted(self, latency_ns=None):
        self.count += 1
        self.window_count += 1
        if latency_ns is not None:
            self.latencies_us.append(max(1, latency_ns // 1000))

    def write_and_reset(self, slot, window_s):
        name = self.topic.encode()[: msg.NAME_LEN]
        slot.topic[: len(name)] = name
        slot.direction, slot.count = self.direction, self.count
        slot.dropped, slot.invalid = self.dropped, self.invalid
        slot.rate_hz = self.window_count / window_s if window_s > 0 else 0.0
        if self.latencies_us:
            ordered, last = sorted(self.latencies_us), len(self.latencies_us) - 1
            slot.latency_p50_us, slot.latency_p99_us, slot.latency_max_us = (
                ordered[last // 2], ordered[last * 99 // 100], ordered[last])
        self.window_count, self.latencies_us = 0, []


class Publisher:
    def __init__(self, node, topic):
        pubsub, event = node.open_services(topic)
        builder = pubsub.publisher_builder().max_loaned_samples(2)
        if node.lockstep:
            builder = builder.backpressure_strategy(iox2.BackpressureStrategy.RetryUntilDelivered)
        self.port = builder.create()
        self.notifier = event.notifier_builder().create()
        self.stats = node.register(topic.name, msg.DIRECTION_PUBLISH)
        self.seq = 0

    def publish(self, tick, origin_ns, fill):
        """Loans a zeroed sample, lets `fill` write the payload in place, stamps, sends."""
        sample = self.port.loan_uninit()
        message = sample.payload().contents
        ctypes.memset(ctypes.addressof(message), 0, ctypes.sizeof(message))
        fill(message)
        message.header.seq, message.header.tick = self.seq, tick
        message.header.stamp_ns, message.header.origin_ns = now_ns(), origin_ns
        sample.assume_init().send()
        self.seq += 1
        self.stats.counted()
        self.notifier.notify()


class Subscriber:
    """A topic's subscriber, read by `rule` (None: the trigger or the map). It drains its queue,
    drops and counts what fails validation, keeps the newest valid sample by tick, and holds
    back a sample newer than `update_through` asked for, for a later step."""

    def __init__(self, topic, port, valid, stats, listener=None, rule=None):
        self.topic, self.port, self.valid, self.stats = topic, port, valid, stats
        self.listener, self.rule = listener, rule
        self.sample, self.pending, self.last_seq = None, [], None

    def update(self):
        """Takes every new message, keeps the newest valid one; returns whether one arrived."""
        return self.update_through(ANY_TICK)

    def update_through(self, tick):
        """`update` up to step `tick`: a newer sample is held back (one per publisher, two
        while a hot swap runs two side by side) and received by a later call."""
        fresh = False
        for held in sorted((s for s in self.pending if s.payload().contents.header.tick <= tick),
                           key=lambda s: s.payload().contents.header.tick):
            self.pending.remove(held)
            fresh |= self._keep_if_newest(held)
        while len(self.pending) < 2 and (sample := self._next_valid()) is not None:
            if sample.payload().contents.header.tick > tick:
                self.pending.append(sample)
            else:
                fresh |= self._keep_if_newest(sample)
        return fresh

    def _keep_if_newest(self, sample):
        """Keeps `sample` as the newest unless it is an older step (a hot swap's old publisher
        may send late); returns whether it was kept."""
        if self.sample is not None and sample.payload().contents.header.tick < self.tick():
            sample.delete()
            return False
        self.release()
        self.sample = sample
        return True

    def _next_valid(self):
        """The next valid sample of the queue, or None; counts the invalid and the dropped."""
        while True:
            try:
                sample = self.port.receive()
            except iox2.ReceiveError:  # every sample it may borrow is held: receive later
                return None
            if sample is None:
                return None
            message = sample.payload().contents
            if not self.valid(message):
                self.stats.invalid += 1
                sample.delete()
                continue
            seq, origin = message.header.seq, message.header.origin_ns
            if self.last_seq is not None and seq > self.last_seq + 1:
                self.stats.dropped += seq - self.last_seq - 1
            self.last_seq = seq
            self.stats.counted(now_ns() - origin if origin else None)
            return sample

    def latest(self):
        return None if self.sample is None else self.sample.payload().contents

    def tick(self):
        return None if self.sample is None else self.latest().header.tick

    def newest_seen(self):
        """The highest step seen: the newest sample's or a held-back one's (a process that
        joined mid-run learns from it that an older step's reading will not come)."""
        ticks = [s.payload().contents.header.tick for s in self.pending]
        return max(ticks + ([] if self.sample is None else [self.tick()]), default=None)

    def release(self):
        """Hands the newest sample back (a subscriber may borrow 2 at most)."""
        if self.sample is not None:
            self.sample.delete()
            self.sample = None

    def close(self):
        """Hands back every sample it holds."""
        self.release()
        for held in self.pending:
            held.delete()
        self.pending = []


class Node:
    """The node mole/<namespace>/<role>, its ports, its wake-ups, its statistics and its step
    loop: declare the trigger, the inputs and the outputs, then `run`."""

    def __init__(self, role, namespace, lockstep, seed=None):
        if iox2 is None:
            raise BadInput("the iceoryx2 Python package is missing: pip install iceoryx2==0.10.0 "
                           "(or run scripts/python-env.sh and use target/python-env/bin/python3)")
        iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
        self.role, self.namespace, self.lockstep, self.seed = role, namespace, lockstep, seed
        self.node = (iox2.NodeBuilder.new()
                     .name(iox2.NodeName.new(f"mole/{namespace}/{role}"))
                     .create(iox2.ServiceType.Ipc))
        self.node.try_cleanup_dead_nodes()
        self.waitset = (iox2.WaitSetBuilder.new()
                        .signal_handling_mode(iox2.SignalHandlingMode.HandleTerminationRequests)
                        .create(iox2.ServiceType.Ipc))
        self.ports, self.subscribers, self.guards = [], [], []
        self.trigger_input, self.inputs = None, []
        self.steps, self.last_stats = 0, now_ns()
        self.stats_publisher = Publisher(self, msg.STACK_STATS)

    def open_services(self, topic):
        name = iox2.ServiceName.new(msg.service_name(self.namespace, topic.name))
        pubsub = (self.node.service_builder(name).publish_subscribe(topic.message)
                  .history_size(topic.history)
                  .subscriber_max_buffer_size(topic.buffer)
                  .subscriber_max_borrowed_samples(2)
                  .max_publishers(topic.max_publishers)
                  .max_subscribers(topic.max_subscribers)
                  .enable_safe_overflow(not self.lockstep)
                  .open_or_create())
        event = (self.node.service_builder(name).event()
                 .max_notifiers(topic.max_publishers + 2)
                 .max_listeners(topic.max_subscribers + 2)
                 .open_or_create())
        return pubsub, event

    def register(self, topic, direction):
        self.ports.append(PortStats(topic, direction))
        return self.ports[-1]

    def publisher(self, topic):
        return Publisher(self, topic)

    def subscriber(self, topic, valid, wakes, rule=None):
        """A subscriber of `topic` keeping what `valid` accepts; a topic that `wakes` ends
        `wait` when published, the others are read when another one woke the process."""
        pubsub, event = self.open_services(topic)
        port = pubsub.subscriber_builder().buffer_size(topic.buffer).create()
        listener = event.listener_builder().create() if wakes else None
        stats = self.register(topic.name, msg.DIRECTION_SUBSCRIBE)
        subscriber = Subscriber(topic.name, port, valid, stats, listener, rule)
        if listener is not None:
            self.guards.append(self.waitset.attach_notification(listener))
        self.subscribers.append(subscriber)
        return subscriber

    def trigger(self, topic, valid):
        """Declares the input whose new tick starts a step (its newest tick, as the Rust
        `Order::Newest`: a process in the loop). It wakes the process."""
        if self.trigger_input is not None:
            raise BadInput(f"{topic.name} is a second trigger: a process has one")
        self.trigger_input = self.subscriber(topic, valid, wakes=True, rule=Rule.SAME_TICK)
        return self.trigger_input

    def input(self, topic, rule, valid):
        """Declares an input read by `rule`. A PREVIOUS_TICK input wakes the process in lockstep
        (it may come after the trigger); the others must be published before the trigger."""
        wakes = rule is Rule.PREVIOUS_TICK and self.lockstep
        self.inputs.append(self.subscriber(topic, valid, wakes, rule))
        return self.inputs[-1]

    def run(self, valid_map, init, step):
        """Until SIGINT or SIGTERM: `init(Start)` once `world/map` (checked by `valid_map`) is
        in, then `step(state, Step)` for every due step, in order."""
        if self.trigger_input is None:
            raise BadInput("a process needs a trigger input")
        world = self.subscriber(msg.WORLD_MAP, valid_map, wakes=True)
        self.ready()
        gate, state = Gate(self.lockstep, self.log), None
        while self.wait():
            if state is None and world.update():
                world_map = world.latest()
                seed = world_map.seed if self.seed is None else self.seed
                state = init(Start(world_map, seed, self.lockstep))
                world.release()
                self.log("map received")
            if state is None:
                continue
            self.step_due(gate, state, step)
        self.close()

    def step_due(self, gate, state, step):
        """Every step the trigger's newest tick makes due, with the inputs its rules need."""
        while True:
            self.trigger_input.update()
            k = self.trigger_input.tick()
            if k is None:
                return
            for port in self.inputs:
                through = receive_through(port.rule, k, self.lockstep)
                if through is not None:
                    port.update_through(through)
            due = gate.due(k, self.inputs)
            if due == "not yet":
                return
            if due == "step":
                step(state, Step(k, self.trigger_input, self.lockstep))
                self.steps += 1

    def ready(self):
        """Every port exists: the first statistics, which the launcher waits for."""
        self.publish_stats()
        self.log(f"ready (namespace {self.namespace}, "
                 f"{'lockstep' if self.lockstep else 'realtime'})")

    def publish_stats(self):
        now = now_ns()
        window_s, self.last_stats = (now - self.last_stats) / 1e9, now
        usage = resource.getrusage(resource.RUSAGE_SELF)

        def fill(stats):
            role = self.role.encode()[: msg.NAME_LEN]
            stats.process[: len(role)] = role
            stats.pid, stats.steps = os.getpid(), self.steps
            stats.cpu_ns = int((usage.ru_utime + usage.ru_stime) * 1e9)
            stats.max_rss_bytes = usage.ru_maxrss * 1024
            ports = self.ports[: msg.MAX_TOPIC_STATS]
            stats.n_topics = len(ports)
            for slot, port in zip(stats.topics, ports):
                port.write_and_reset(slot, window_s)

        self.stats_publisher.publish(self.steps, 0, fill)

    def wait(self):
        """Sleeps until a topic that wakes is published or the statistics are due (and
        publishes them); False once SIGINT or SIGTERM arrived."""
        if now_ns() - self.last_stats >= STATS_PERIOD_NS:
            self.publish_stats()
        timeout = iox2.Duration.from_nanos(max(0, self.last_stats + STATS_PERIOD_NS - now_ns()))
        _, result = self.waitset.wait_and_process_with_timeout(timeout)
        for subscriber in self.subscribers:  # consume the wake-ups, or the WaitSet spins
            if subscriber.listener is not None:
                subscriber.listener.try_wait()
        return result not in (iox2.WaitSetRunResult.TerminationRequest,
                              iox2.WaitSetRunResult.Interrupt)

    def close(self):
        for subscriber in self.subscribers:
            subscriber.close()
        self.guards.clear()
        self.log(f"stopped after {self.steps} steps")

    def log(self, text, level="INFO"):
        print(f"{time.strftime('%H:%M:%S')} {level} {self.role}: {text}", file=sys.stderr,
              flush=True)
