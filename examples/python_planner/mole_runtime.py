"""The stack's conventions for a Python process: what processes/runtime does for the Rust ones.

- The node is `mole/<namespace>/<role>`; a topic is the publish-subscribe service
  `mole/<namespace>/<topic>` plus an event service of the same name, both opened with the
  settings the runtime gives them (else iceoryx2 refuses the open as incompatible).
- A publisher loans a sample, writes it in place, stamps the header (seq, tick, stamp_ns =
  CLOCK_MONOTONIC, origin_ns), sends it and notifies the event. Lockstep never drops: a full
  subscriber makes the publisher wait; realtime drops the oldest sample.
- A subscriber drains its queue, drops and counts what fails validation, keeps the newest
  (by tick).
- Statistics go out on stack/stats once a second; the first one tells the launcher "ready".
- SIGINT/SIGTERM end the wait: iceoryx2's WaitSet handles them here.
"""

import ctypes
import os
import resource
import sys
import time

import mole_messages as msg

try:
    import iceoryx2 as iox2
except ImportError:
    print("error: the iceoryx2 Python package is missing: pip install iceoryx2==0.10.0 "
          "(or run scripts/python-env.sh and use target/python-env/bin/python3)", file=sys.stderr)
    sys.exit(2)

STATS_PERIOD_NS = 1_000_000_000


class BadInput(Exception):
    """Input a process refuses: exit code 2, which no restart policy retries."""


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
    def __init__(self, node, topic, valid):
        pubsub, event = node.open_services(topic)
        self.port = pubsub.subscriber_builder().buffer_size(topic.buffer).create()
        self.listener = event.listener_builder().create()
        self.stats = node.register(topic.name, msg.DIRECTION_SUBSCRIBE)
        self.valid, self.sample, self.last_seq = valid, None, None

    def update(self):
        """Takes every new message, keeps the newest valid one; returns whether one arrived."""
        fresh = False
        while (sample := self.port.receive()) is not None:
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
            if self.sample is not None and message.header.tick < self.tick():
                # Newest by tick, not by arrival (a hot swap's old publisher may send late).
                sample.delete()
                continue
            self.release()
            self.sample, fresh = sample, True
        return fresh

    def latest(self):
        return None if self.sample is None else self.sample.payload().contents

    def tick(self):
        return None if self.sample is None else self.latest().header.tick

    def release(self):
        """Hands the newest sample back (a subscriber may borrow 2 at most)."""
        if self.sample is not None:
            self.sample.delete()
            self.sample = None


class Node:
    """The node mole/<namespace>/<role>, its ports, its wake-ups and its statistics."""

    def __init__(self, role, namespace, lockstep):
        iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
        self.role, self.namespace, self.lockstep = role, namespace, lockstep
        self.node = (iox2.NodeBuilder.new()
                     .name(iox2.NodeName.new(f"mole/{namespace}/{role}"))
                     .create(iox2.ServiceType.Ipc))
        self.node.try_cleanup_dead_nodes()
        self.waitset = (iox2.WaitSetBuilder.new()
                        .signal_handling_mode(iox2.SignalHandlingMode.HandleTerminationRequests)
                        .create(iox2.ServiceType.Ipc))
        self.ports, self.subscribers, self.guards = [], [], []
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

    def subscriber(self, topic, valid=lambda message: True):
        """A subscriber whose topic wakes `wait`; `valid` says which messages to keep."""
        subscriber = Subscriber(self, topic, valid)
        self.guards.append(self.waitset.attach_notification(subscriber.listener))
        self.subscribers.append(subscriber)
        return subscriber

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
        """Sleeps until a subscribed topic is published or the statistics are due (and
        publishes them); False once SIGINT or SIGTERM arrived."""
        if now_ns() - self.last_stats >= STATS_PERIOD_NS:
            self.publish_stats()
        timeout = iox2.Duration.from_nanos(max(0, self.last_stats + STATS_PERIOD_NS - now_ns()))
        _, result = self.waitset.wait_and_process_with_timeout(timeout)
        for subscriber in self.subscribers:  # consume the wake-ups, or the WaitSet spins
            subscriber.listener.try_wait()
        return result not in (iox2.WaitSetRunResult.TerminationRequest,
                              iox2.WaitSetRunResult.Interrupt)

    def close(self):
        for subscriber in self.subscribers:
            subscriber.release()
        self.guards.clear()
        self.log(f"stopped after {self.steps} steps")

    def log(self, text):
        print(f"{time.strftime('%H:%M:%S')} INFO {self.role}: {text}", file=sys.stderr, flush=True)
