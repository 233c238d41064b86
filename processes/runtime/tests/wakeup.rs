//! The wake-up path: a mole publisher rings the doorbell of each node that listens to its topic
//! (one byte in a pipe) instead of sending an iceoryx2 datagram per listener; programs that are
//! not mole Rust processes still wake and are woken through the topic's event service; a lost
//! signal costs a look-again interval; in realtime a process beside the loop wakes when the
//! loop's command is published; and a doorbell leaves nothing behind.

use iceoryx2::prelude::*;
use mole_runtime::{ClockMode, CommonArgs, Context, Order, Process, Wake, Waker};
use mole_types::topics;
use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use std::os::fd::BorrowedFd;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// Guards a wait against sleeping forever; never a measured limit.
const NO_HANG: Duration = Duration::from_secs(10);

fn args(test: &str, mode: ClockMode) -> CommonArgs {
    CommonArgs::attach(&format!("rt-wake-{test}-{}", std::process::id()), mode)
}

fn context(role: &str, args: &CommonArgs) -> Context {
    Context::with_shutdown_flag(role, args, Arc::new(AtomicBool::new(false))).expect("context")
}

/// Whether something waits to be read on `fd` (a doorbell ring, a listener's datagram).
fn readable(fd: BorrowedFd<'_>) -> bool {
    let mut watched = [PollFd::new(fd, PollFlags::POLLIN)];
    poll(&mut watched, PollTimeout::ZERO).expect("poll") > 0
}

/// Takes the rings waiting in a doorbell behind its WaitSet's back; returns how many there were.
fn take_rings(ctx: &Context) -> usize {
    match nix::unistd::read(ctx.doorbell_fd(), &mut [0u8; 64]) {
        Ok(n) => n,
        Err(nix::errno::Errno::EAGAIN) => 0,
        Err(e) => panic!("read the doorbell: {e}"),
    }
}

/// Whether a wake-up datagram waits in the listener's socket.
fn datagram_pending(waker: &Waker) -> bool {
    readable(waker.listener_fd().expect("an active subscriber"))
}

/// Reads the datagrams out of a listener's socket behind iceoryx2's back; how many it read.
fn lose_datagrams(waker: &Waker) -> usize {
    let socket = waker.listener_fd().expect("an active subscriber");
    let mut lost = 0;
    while readable(socket) {
        nix::unistd::read(socket, &mut [0u8; 64]).expect("read a datagram");
        lost += 1;
    }
    lost
}

fn publish_cmd(cmd_pub: &mut mole_runtime::Publisher<mole_types::Cmd>, tick: u64) {
    cmd_pub
        .publish(tick, 1, |c| {
            c.v = 0.1;
            c.omega = 0.0;
            c.mode = 0;
            c._pad = 0;
        })
        .unwrap();
}

/// A program that is not a mole Rust process (the Python runtime, iceoryx2's tools): a plain
/// iceoryx2 node on the topic's event service.
struct Foreign {
    event: iceoryx2::service::port_factory::event::PortFactory<ipc::Service>,
    _node: Node<ipc::Service>,
}

impl Foreign {
    fn on(namespace: &str, topic: &str) -> Foreign {
        let node = NodeBuilder::new()
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .unwrap();
        let name = topics::service_name(namespace, topic);
        let name: ServiceName = name.as_str().try_into().unwrap();
        let event = node.service_builder(&name).event().open().unwrap();
        Foreign { event, _node: node }
    }
}

/// Two publishes on two topics of one node, whose first topic it listens to twice, ring its
/// doorbell once each and send no datagram; one wait empties the doorbell.
#[test]
fn a_mole_publisher_rings_each_listening_node_once_and_sends_no_datagram() {
    let args = args("ring", ClockMode::Realtime);
    let producer = context("producer", &args);
    let mut consumer = context("consumer", &args);
    let mut cmd_pub = producer.publisher(topics::PLANNING_CMD).unwrap();
    let mut odom_pub = producer.publisher(topics::SENSING_ODOM).unwrap();
    let cmd_sub = consumer.subscriber(topics::PLANNING_CMD).unwrap();
    let cmd_again = consumer.subscriber(topics::PLANNING_CMD).unwrap();
    let mut odom_sub = consumer.subscriber(topics::SENSING_ODOM).unwrap();
    let waitset = consumer.waitset().unwrap();
    let wakers = [cmd_sub.waker(), cmd_again.waker(), odom_sub.waker()];
    let _attached = waitset.attach_all(&wakers).unwrap();

    publish_cmd(&mut cmd_pub, 1);
    assert_eq!(
        take_rings(&consumer),
        1,
        "one ring for two listeners of one node"
    );
    publish_cmd(&mut cmd_pub, 2);
    odom_pub
        .publish(2, 1, |m| (m.v, m.omega, m.dt) = (0.0, 0.0, 0.01))
        .unwrap();
    for (i, waker) in wakers.iter().enumerate() {
        assert!(
            !datagram_pending(waker),
            "listener {i}: a datagram was sent"
        );
    }
    let wake = waitset
        .wait(&mut consumer, Some(Instant::now() + NO_HANG))
        .unwrap();
    assert_eq!(wake, Wake::Data);
    assert!(
        !readable(consumer.doorbell_fd()),
        "one wait takes every ring"
    );
    assert!(odom_sub.update());
    assert_eq!(odom_sub.tick(), Some(2));
}

/// Programs that are not mole Rust processes keep the iceoryx2 protocol: their notification
/// wakes a mole process, and a mole publisher notifies their listener.
#[test]
fn other_programs_wake_and_are_woken_through_the_event_service() {
    let args = args("foreign", ClockMode::Realtime);
    let producer = context("producer", &args);
    let mut consumer = context("consumer", &args);
    let mut cmd_pub = producer.publisher(topics::PLANNING_CMD).unwrap();
    let mut cmd_sub = consumer.subscriber(topics::PLANNING_CMD).unwrap();
    let waitset = consumer.waitset().unwrap();
    let cmd_wake = cmd_sub.waker();
    let _attached = waitset.attach(&cmd_wake).unwrap();
    let foreign = Foreign::on(&args.namespace, topics::PLANNING_CMD.name);

    let notifier = foreign.event.notifier_builder().create().unwrap();
    notifier.notify().unwrap();
    let wake = waitset
        .wait(&mut consumer, Some(Instant::now() + NO_HANG))
        .unwrap();
    assert_eq!(wake, Wake::Data, "a foreign notification wakes the WaitSet");
    assert!(!datagram_pending(&cmd_wake), "the wait took the datagram");

    let listener = foreign.event.listener_builder().create().unwrap();
    publish_cmd(&mut cmd_pub, 3);
    let mut events = 0;
    listener
        .timed_wait(|_| events += 1, NO_HANG)
        .expect("wait on the foreign listener");
    assert_eq!(events, 1, "a mole publish notifies a foreign listener");
    let wake = waitset
        .wait(&mut consumer, Some(Instant::now() + NO_HANG))
        .unwrap();
    assert_eq!(wake, Wake::Data);
    assert!(cmd_sub.update());
    assert_eq!(cmd_sub.tick(), Some(3));
}

/// A ring that never reaches the WaitSet (taken behind its back) costs one look-again interval:
/// the wait still returns with the sample, found by looking at the queues.
#[test]
fn a_lost_ring_is_found_by_looking() {
    for mode in [ClockMode::Lockstep, ClockMode::Realtime] {
        let args = args(&format!("lost-ring-{mode}"), mode);
        let producer = context("producer", &args);
        let mut consumer = context("consumer", &args);
        let mut cmd_pub = producer.publisher(topics::PLANNING_CMD).unwrap();
        let mut cmd_sub = consumer.subscriber(topics::PLANNING_CMD).unwrap();
        let waitset = consumer.waitset().unwrap();
        let cmd_wake = cmd_sub.waker();
        let _attached = waitset.attach(&cmd_wake).unwrap();

        publish_cmd(&mut cmd_pub, 1);
        assert_eq!(take_rings(&consumer), 1, "{mode}: step 1 rang");
        // Lockstep looks again after LOCKSTEP_RECHECK without a deadline; realtime when its
        // statistics are due. The deadline only guards against sleeping forever.
        let deadline = match mode {
            ClockMode::Lockstep => None,
            ClockMode::Realtime => Some(Instant::now() + NO_HANG),
        };
        let wake = waitset.wait(&mut consumer, deadline).unwrap();
        assert_eq!(wake, Wake::Data, "{mode}: step 1 came without its ring");
        assert!(cmd_sub.update());
        assert_eq!(cmd_sub.tick(), Some(1), "{mode}");
    }
}

/// iceoryx2 0.10 can leave a listener "notified" with an empty socket (a datagram lost while it
/// was emptied; eclipse-iceoryx/iceoryx2#1811), which swallows every later notification of other
/// programs. A wait that ends without a signal resets it, and still returns with the sample.
#[test]
fn a_listener_that_swallows_foreign_notifications_is_reset_by_a_wait_without_signal() {
    for mode in [ClockMode::Lockstep, ClockMode::Realtime] {
        let args = args(&format!("stuck-listener-{mode}"), mode);
        let producer = context("producer", &args);
        let mut consumer = context("consumer", &args);
        let mut cmd_pub = producer.publisher(topics::PLANNING_CMD).unwrap();
        let mut cmd_sub = consumer.subscriber(topics::PLANNING_CMD).unwrap();
        let waitset = consumer.waitset().unwrap();
        let cmd_wake = cmd_sub.waker();
        let _attached = waitset.attach(&cmd_wake).unwrap();
        let foreign = Foreign::on(&args.namespace, topics::PLANNING_CMD.name);
        let notifier = foreign.event.notifier_builder().create().unwrap();

        // Step 1: its ring and its foreign datagram both lost.
        publish_cmd(&mut cmd_pub, 1);
        notifier.notify().unwrap();
        take_rings(&consumer);
        assert_eq!(lose_datagrams(&cmd_wake), 1, "{mode}: step 1 notified");
        assert!(cmd_sub.update());
        // Step 2: the listener swallows the foreign notification; its ring is lost too.
        publish_cmd(&mut cmd_pub, 2);
        notifier.notify().unwrap();
        take_rings(&consumer);
        assert!(
            !datagram_pending(&cmd_wake),
            "{mode}: iceoryx2 no longer coalesces a notification away after a lost one: this \
             test does not reproduce the race any more"
        );
        let deadline = match mode {
            ClockMode::Lockstep => None,
            ClockMode::Realtime => Some(Instant::now() + NO_HANG),
        };
        let wake = waitset.wait(&mut consumer, deadline).unwrap();
        assert_eq!(wake, Wake::Data, "{mode}: step 2 came without a signal");
        assert!(cmd_sub.update());
        assert_eq!(cmd_sub.tick(), Some(2), "{mode}");
        // The wait reset the listener: a foreign notification reaches it again.
        notifier.notify().unwrap();
        assert!(
            datagram_pending(&cmd_wake),
            "{mode}: the listener still swallows every foreign notification"
        );
    }
}

/// Realtime: a process beside the loop (an every-tick trigger, an observer) is not rung by its
/// inputs but by the loop's command; in lockstep its inputs ring it.
#[test]
fn beside_the_loop_a_realtime_process_wakes_on_the_command_not_its_inputs() {
    for mode in [ClockMode::Realtime, ClockMode::Lockstep] {
        let args = args(&format!("beside-{mode}"), mode);
        let feed = context("feed", &args);
        let mut pose_pub = feed.publisher(topics::LOCALIZATION_POSE).unwrap();
        let mut truth_pub = feed.publisher(topics::WORLD_TRUTH).unwrap();
        let mut cmd_pub = feed.publisher(topics::PLANNING_CMD).unwrap();
        let shutdown = Arc::new(AtomicBool::new(false));
        let mut mapper = Process::with_shutdown_flag("mapper", &args, shutdown.clone()).unwrap();
        mapper
            .trigger(topics::LOCALIZATION_POSE, Order::EveryTick)
            .unwrap();
        let mut observer = Process::with_shutdown_flag("observer", &args, shutdown).unwrap();
        observer.observed(topics::WORLD_TRUTH, true).unwrap();
        let realtime = mode == ClockMode::Realtime;
        for p in [&mapper, &observer] {
            assert_eq!(p.wakes_after_the_loop(), realtime, "{mode}");
        }

        pose_pub.publish(0, 1, |_| {}).unwrap();
        truth_pub.publish(0, 1, |_| {}).unwrap();
        for (p, role) in [(&mapper, "mapper"), (&observer, "observer")] {
            assert_eq!(
                take_rings(p.context()),
                usize::from(!realtime),
                "{mode}: its input rings the {role}"
            );
        }
        publish_cmd(&mut cmd_pub, 0);
        for (p, role) in [(&mapper, "mapper"), (&observer, "observer")] {
            assert_eq!(
                take_rings(p.context()),
                usize::from(realtime),
                "{mode}: the command rings the {role}"
            );
        }
    }
}

/// Where a doorbell is: the named pipe its descriptor was opened from.
fn doorbell_path(ctx: &Context) -> std::path::PathBuf {
    use std::os::fd::AsRawFd;
    std::fs::read_link(format!("/proc/self/fd/{}", ctx.doorbell_fd().as_raw_fd()))
        .expect("the doorbell's path")
}

/// A node's doorbell goes with it; one a killed process left is swept like its node's records,
/// once old enough that it cannot be one a starting node is making.
#[test]
fn a_doorbell_goes_with_its_node_and_the_sweep_removes_a_dead_ones() {
    use std::os::unix::fs::FileTypeExt;
    let args = args("sweep", ClockMode::Realtime);
    let ctx = context("sweeper", &args);
    let path = doorbell_path(&ctx);
    assert!(
        std::fs::symlink_metadata(&path).is_ok_and(|m| m.file_type().is_fifo()),
        "{} is a named pipe",
        path.display()
    );
    mole_runtime::cleanup_dead_nodes();
    assert!(path.exists(), "a live node's doorbell survives the sweep");
    drop(ctx);
    assert!(!path.exists(), "{} outlived its node", path.display());

    // Left by a node that no longer exists (its records are gone).
    let dir = path.parent().expect("the doorbells' directory");
    let left = dir.join(format!("{}", u128::MAX - u128::from(std::process::id())));
    let _ = std::fs::remove_file(&left);
    nix::unistd::mkfifo(&left, nix::sys::stat::Mode::S_IRWXU).expect("make a doorbell");
    let cleanup = RemoveOnDrop(left.clone());
    mole_runtime::cleanup_dead_nodes();
    assert!(
        left.exists(),
        "a doorbell just made may be a starting node's"
    );
    let old = nix::sys::time::TimeVal::new(1_000_000_000, 0);
    nix::sys::stat::utimes(&left, &old, &old).expect("age the doorbell");
    mole_runtime::cleanup_dead_nodes();
    assert!(!left.exists(), "a dead node's doorbell was not swept");
    drop(cleanup);
}

/// Removes a file when the test ends, passed or failed.
struct RemoveOnDrop(std::path::PathBuf);

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}
