//! The step loop's rules against real iceoryx2 queues: which sample of each input a step gets,
//! in lockstep and in realtime, when inputs come early, late or not at all.

mod common;

use mole_runtime::{ClockMode, CommonArgs, Context, In, Order, Process, Publisher, Rule};
use mole_types::{Fix, Grid, Odom, Scan, topics};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

/// What one step saw: its tick, and the tick of each non-trigger input's sample (if any).
type Seen = (u64, Option<u64>, Option<u64>, Option<u64>);

fn args(test: &str, mode: ClockMode) -> CommonArgs {
    CommonArgs::attach(&format!("rt-step-{test}-{}", std::process::id()), mode)
}

/// A process like planning: odom triggers (by `order`), the fix is the same tick, the grid the
/// previous tick, the scan the newest. It reports every step it handles, until shut down.
fn start_process(
    args: CommonArgs,
    order: Order,
    shutdown: Arc<AtomicBool>,
) -> (std::thread::JoinHandle<()>, mpsc::Receiver<Seen>) {
    let (tx, rx) = mpsc::channel();
    let (ready_tx, ready_rx) = mpsc::channel();
    let handle = std::thread::spawn(move || {
        let mut p = Process::with_shutdown_flag("stepper", &args, shutdown).unwrap();
        let odom = p.trigger(topics::SENSING_ODOM, order).unwrap();
        let fix: In<Fix> = p.input(topics::SENSING_FIX, Rule::SameTick).unwrap();
        let grid: In<Grid> = p.input(topics::MAPPING_GRID, Rule::PreviousTick).unwrap();
        let scan: In<Scan> = p.input(topics::SENSING_SCAN, Rule::Newest).unwrap();
        ready_tx.send(()).unwrap();
        p.run(
            |_| Ok(()),
            |_, step| {
                assert_eq!(step.trigger(odom).header.tick, step.tick());
                let tick = |m: Option<&mole_types::Header>| m.map(|h| h.tick);
                tx.send((
                    step.tick(),
                    tick(step.get(fix).map(|m| &m.header)),
                    tick(step.get(grid).map(|m| &m.header)),
                    tick(step.get(scan).map(|m| &m.header)),
                ))
                .unwrap();
                Ok(())
            },
        )
        .unwrap();
    });
    ready_rx.recv_timeout(Duration::from_secs(10)).unwrap();
    (handle, rx)
}

struct Feed {
    _ctx: Context,
    map: Publisher<mole_types::WorldMap>,
    odom: Publisher<Odom>,
    fix: Publisher<Fix>,
    grid: Publisher<Grid>,
    scan: Publisher<Scan>,
}

impl Feed {
    fn new(args: &CommonArgs) -> Feed {
        let ctx =
            Context::with_shutdown_flag("feed", args, Arc::new(AtomicBool::new(false))).unwrap();
        Feed {
            map: ctx.publisher(topics::WORLD_MAP).unwrap(),
            odom: ctx.publisher(topics::SENSING_ODOM).unwrap(),
            fix: ctx.publisher(topics::SENSING_FIX).unwrap(),
            grid: ctx.publisher(topics::MAPPING_GRID).unwrap(),
            scan: ctx.publisher(topics::SENSING_SCAN).unwrap(),
            _ctx: ctx,
        }
    }
    fn map(&mut self) {
        common::publish_map(&mut self.map);
    }
    fn odom(&mut self, k: u64) {
        common::publish_odom(&mut self.odom, k);
    }
    fn fix(&mut self, k: u64) {
        self.fix.publish(k, 1, |m| m.std = 0.1).unwrap();
    }
    fn grid(&mut self, k: u64) {
        self.grid
            .publish(k, 1, |m| (m.width, m.height, m.resolution) = (1, 1, 0.1))
            .unwrap();
    }
    fn scan(&mut self, k: u64) {
        self.scan
            .publish(k, 1, |m| (m.n_beams, m.range_max) = (0, 1.0))
            .unwrap();
    }
}

fn next(rx: &mpsc::Receiver<Seen>) -> Seen {
    rx.recv_timeout(Duration::from_secs(10))
        .expect("a step within 10 s")
}

fn nothing(rx: &mpsc::Receiver<Seen>) -> bool {
    rx.recv_timeout(Duration::from_millis(300)).is_err()
}

#[test]
fn lockstep_waits_for_the_same_tick_and_takes_the_previous_grid_even_when_a_newer_one_came() {
    let args = args("lockstep", ClockMode::Lockstep);
    let mut feed = Feed::new(&args);
    let shutdown = Arc::new(AtomicBool::new(false));
    let (handle, rx) = start_process(args, Order::Newest, shutdown.clone());
    feed.map();
    feed.scan(0);
    feed.odom(0);
    assert!(nothing(&rx), "step 0 waits for its fix");
    feed.fix(0);
    assert_eq!(
        next(&rx),
        (0, Some(0), None, Some(0)),
        "step 0 has no previous grid"
    );
    feed.fix(1);
    feed.odom(1);
    assert!(nothing(&rx), "step 1 waits for the grid of step 0");
    // Mapping ran ahead: grids 0 and 1 are both in before step 1 is handled.
    feed.grid(0);
    feed.grid(1);
    assert_eq!(
        next(&rx),
        (1, Some(1), Some(0), Some(0)),
        "grid k−1, never k"
    );
    feed.fix(2);
    feed.odom(2);
    assert_eq!(
        next(&rx),
        (2, Some(2), Some(1), Some(0)),
        "the held grid 1 now"
    );
    shutdown.store(true, Ordering::SeqCst);
    handle.join().unwrap();
}

#[test]
fn realtime_steps_on_each_new_trigger_and_a_missed_reading_is_none_not_last_steps() {
    let args = args("realtime", ClockMode::Realtime);
    let mut feed = Feed::new(&args);
    let shutdown = Arc::new(AtomicBool::new(false));
    let (handle, rx) = start_process(args, Order::Newest, shutdown.clone());
    feed.map();
    feed.fix(0);
    feed.grid(0);
    feed.odom(0);
    assert_eq!(next(&rx), (0, Some(0), Some(0), None));
    feed.odom(1); // no fix for step 1
    assert_eq!(
        next(&rx),
        (1, None, Some(0), None),
        "no fix of step 1: None"
    );
    feed.odom(1);
    assert!(nothing(&rx), "a tick already handled is not a step again");
    shutdown.store(true, Ordering::SeqCst);
    handle.join().unwrap();
}

#[test]
fn every_tick_in_order_handles_each_queued_step_and_joins_a_run_under_way() {
    let args = args("in-order", ClockMode::Lockstep);
    let mut feed = Feed::new(&args);
    // Steps 0 and 1 were sent before the process listened: only their odometry is queued
    // (history 0: nothing), so it starts from what comes next.
    let shutdown = Arc::new(AtomicBool::new(false));
    let (handle, rx) = start_process(args, Order::EveryTick, shutdown.clone());
    feed.map();
    // The process fell behind: three steps queued at once, and step 2's fix is missing
    // because it was sent before this process listened (a late join).
    for k in 2..5 {
        if k != 2 {
            feed.fix(k);
        }
        feed.odom(k);
        feed.grid(k - 1);
    }
    assert_eq!(
        next(&rx),
        (3, Some(3), Some(2), None),
        "step 2 skipped: its fix never comes"
    );
    assert_eq!(
        next(&rx),
        (4, Some(4), Some(3), None),
        "then every step, in order"
    );
    shutdown.store(true, Ordering::SeqCst);
    handle.join().unwrap();
}

/// A role's main that declares other ports than the graph's row fails at start, naming what it
/// declared and what the graph says; the graph's own ports start.
#[test]
fn a_role_whose_ports_differ_from_the_graph_fails_at_start() {
    let args = args("graph", ClockMode::Lockstep);
    // Shut down from the start: a process that passes the check returns at its first wait.
    let shutdown = Arc::new(AtomicBool::new(true));
    // Mapping's ports with `tactile` read or not, and the contact grid written or not.
    let run = |tactile: bool, contact: bool| {
        let mut p = Process::with_shutdown_flag("mapping", &args, shutdown.clone()).unwrap();
        let _pose = p
            .trigger(topics::LOCALIZATION_POSE, Order::EveryTick)
            .unwrap();
        let _scan: In<Scan> = p.input(topics::SENSING_SCAN, Rule::SameTick).unwrap();
        let _touch: Option<In<mole_types::Tactile>> =
            tactile.then(|| p.input(topics::SENSING_TACTILE, Rule::SameTick).unwrap());
        let _grid = p.output(topics::MAPPING_GRID).unwrap();
        let _contact = contact.then(|| p.output(topics::MAPPING_CONTACT).unwrap());
        p.run(|_| Ok(()), |_: &mut (), _| Ok(()))
            .map_err(|e| e.to_string())
    };
    let err = run(false, true).expect_err("an input short");
    assert!(err.contains("the mapping process reads"), "{err}");
    assert!(
        err.contains("\"sensing/tactile\"") && err.contains("GRAPH"),
        "{err}"
    );
    let err = run(true, false).expect_err("an output short");
    assert!(
        err.contains("the mapping process writes [\"mapping/grid\"]"),
        "{err}"
    );
    run(true, true).expect("the graph's ports start (and stop at once)");
}
