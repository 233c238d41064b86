//! Two robots on one machine: a process reads what another robot's stack (another namespace)
//! offers, against real iceoryx2 queues, in lockstep, where an ordinary topic's full queue makes
//! its publisher wait. The peer's input never gates a step, and a reader that does not step
//! never holds the peer back.

mod common;

use mole_runtime::{ClockMode, CommonArgs, Context, Order, Process, Publisher, RuntimeError};
use mole_types::{Odom, Topic, WorldMap, topics};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

/// What a robot offers its peers in these tests (its odometry stands in for its map).
const OFFER: Topic<Odom> = Topic::new("peers/test/odom").buffer(1);

/// What one step of robot B saw: its tick and the tick of the peer's newest offer, if any.
type Seen = (u64, Option<u64>);

/// Lockstep arguments of robot `robot` in test `test`.
fn args(test: &str, robot: &str) -> CommonArgs {
    CommonArgs::attach(
        &format!("rt-peer-{test}-{robot}-{}", std::process::id()),
        ClockMode::Lockstep,
    )
}

/// A context of robot `args`, for publishing by hand.
fn context(args: &CommonArgs, role: &str) -> Context {
    Context::with_shutdown_flag(role, args, Arc::new(AtomicBool::new(false))).unwrap()
}

/// Robot B's localization in miniature: its odometry triggers a step, and it reads robot A's
/// offer as a peer input. It reports every step it handles until shut down.
fn start_robot_b(
    b: CommonArgs,
    a_namespace: String,
    shutdown: Arc<AtomicBool>,
) -> (std::thread::JoinHandle<()>, mpsc::Receiver<Seen>) {
    let (tx, rx) = mpsc::channel();
    let (ready_tx, ready_rx) = mpsc::channel();
    let handle = std::thread::spawn(move || {
        let mut p = Process::with_shutdown_flag("fuser", &b, shutdown).unwrap();
        let odom = p.trigger(topics::SENSING_ODOM, Order::Newest).unwrap();
        let peer = p.peer_input(&a_namespace, OFFER).unwrap();
        ready_tx.send(()).unwrap();
        p.run(
            |_| Ok(()),
            |_, step| {
                assert_eq!(step.trigger(odom).header.tick, step.tick());
                let peer_tick = step.get(peer).map(|m| m.header.tick);
                tx.send((step.tick(), peer_tick)).unwrap();
                Ok(())
            },
        )
        .unwrap();
    });
    ready_rx.recv_timeout(Duration::from_secs(10)).unwrap();
    (handle, rx)
}

/// Robot B's own stack, fed by hand: the world's map and the odometry.
struct StackB {
    _ctx: Context,
    map: Publisher<WorldMap>,
    odom: Publisher<Odom>,
}

impl StackB {
    fn new(b: &CommonArgs) -> StackB {
        let ctx = context(b, "feed");
        StackB {
            map: ctx.publisher(topics::WORLD_MAP).unwrap(),
            odom: ctx.publisher(topics::SENSING_ODOM).unwrap(),
            _ctx: ctx,
        }
    }
    fn map(&mut self) {
        common::publish_map(&mut self.map);
    }
    fn odom(&mut self, k: u64) {
        common::publish_odom(&mut self.odom, k);
    }
}

/// Publishes the offer of ticks `ticks` from `offer`.
fn offer(offer: &mut Publisher<Odom>, ticks: std::ops::Range<u64>) {
    for k in ticks {
        offer
            .publish(k, 1, |m| (m.v, m.omega, m.dt) = (0.0, 0.0, 0.01))
            .unwrap();
    }
}

fn next(rx: &mpsc::Receiver<Seen>) -> Seen {
    rx.recv_timeout(Duration::from_secs(10))
        .expect("a step within 10 s")
}

/// Robot B steps in lockstep with nothing from its peer (the peer never gates a step), then
/// reads robot A's offer: A's, not the offer of the same topic in B's own namespace.
#[test]
fn a_peer_input_reads_the_other_robots_offer_and_never_gates_a_lockstep_step() {
    let (a, b) = (args("reads", "a"), args("reads", "b"));
    let mut stack_b = StackB::new(&b);
    let mut offer_of_b = context(&b, "offer").peer_publisher(OFFER).unwrap();
    let shutdown = Arc::new(AtomicBool::new(false));
    let (handle, rx) = start_robot_b(b, a.namespace.clone(), shutdown.clone());
    stack_b.map();
    stack_b.odom(0);
    assert_eq!(next(&rx), (0, None), "step 0 without the peer's offer");
    let robot_a = context(&a, "localization");
    let mut offer_of_a = robot_a.peer_publisher(OFFER).unwrap();
    offer(&mut offer_of_a, 7..8);
    offer(&mut offer_of_b, 99..100);
    stack_b.odom(1);
    assert_eq!(next(&rx), (1, Some(7)), "robot A's offer, tick 7");
    stack_b.odom(2);
    assert_eq!(
        next(&rx),
        (2, Some(7)),
        "the newest offer stays until a newer one comes"
    );
    shutdown.store(true, Ordering::SeqCst);
    handle.join().unwrap();
}

/// Robot A offers five samples in lockstep while robot B, its reader, is not stepping (its
/// world has not started): A never waits for B, whose queue keeps the newest, tick 4. An
/// ordinary lockstep queue would have held A back and kept the oldest, tick 0.
#[test]
fn an_offer_never_waits_for_a_peer_that_does_not_step() {
    let (a, b) = (args("never-waits", "a"), args("never-waits", "b"));
    let a_namespace = a.namespace.clone();
    let mut stack_b = StackB::new(&b);
    let shutdown = Arc::new(AtomicBool::new(false));
    let (handle, rx) = start_robot_b(b, a_namespace, shutdown.clone());
    // Robot A in a thread of its own, alive until B has read (a publisher that goes away takes
    // its undelivered samples with it).
    let (published_tx, published_rx) = mpsc::channel();
    let (release_tx, release_rx) = mpsc::channel::<()>();
    let robot_a = std::thread::spawn(move || {
        let robot_a = context(&a, "localization");
        let mut offer_of_a = robot_a.peer_publisher(OFFER).unwrap();
        offer(&mut offer_of_a, 0..5);
        published_tx.send(()).unwrap();
        let _ = release_rx.recv_timeout(Duration::from_secs(60));
    });
    // Only a guard against hanging forever: a publisher held back waits while B does not step.
    published_rx
        .recv_timeout(Duration::from_secs(60))
        .expect("robot A published its five samples");
    stack_b.map();
    stack_b.odom(0);
    assert_eq!(next(&rx), (0, Some(4)), "the newest of A's offers");
    release_tx.send(()).unwrap();
    robot_a.join().unwrap();
    shutdown.store(true, Ordering::SeqCst);
    handle.join().unwrap();
}

/// A peer reads only what a robot offers: an ordinary lockstep topic of another stack (whose
/// full queue would make its publisher wait) and this robot's own namespace are refused, each
/// with the reason.
#[test]
fn a_peer_cannot_read_an_ordinary_lockstep_topic_nor_its_own_namespace() {
    let (a, b) = (args("refused", "a"), args("refused", "b"));
    let robot_a = context(&a, "localization");
    let _ordinary = robot_a.publisher(topics::SENSING_ODOM).unwrap();
    let mut p = Process::with_shutdown_flag("fuser", &b, Arc::new(AtomicBool::new(false))).unwrap();
    let refused = |result: Result<_, RuntimeError>| result.err().map(|e| e.to_string());
    let ordinary = refused(p.peer_input(&a.namespace, topics::SENSING_ODOM));
    assert!(
        ordinary
            .as_deref()
            .is_some_and(|e| e.contains("ordinary topic")),
        "{ordinary:?}"
    );
    let own = refused(p.peer_input(&b.namespace, OFFER));
    assert!(
        own.as_deref().is_some_and(|e| e.contains("own namespace")),
        "{own:?}"
    );
}
