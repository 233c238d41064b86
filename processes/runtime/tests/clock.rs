//! The clock's loop (`Process::run_clock`) against real iceoryx2 queues: what a process that
//! joins a lockstep run late is handed while the clock waits for a reply.

use mole_runtime::{ClockEvent, ClockMode, CommonArgs, Context, Flow, Order, Process};
use mole_types::topics;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

fn args(test: &str) -> CommonArgs {
    CommonArgs::attach(
        &format!("rt-clock-{test}-{}", std::process::id()),
        ClockMode::Lockstep,
    )
}

/// A process swapped in while the clock waits for a reply (its predecessor gone) is handed the
/// map and the step from history in time to answer, so the clock never publishes that step
/// again: the late process sees step 0 once, then step 1. The clock resends after a second
/// without a reply; were history offered only then (as it once was), the late process would
/// see step 0 twice, and a swap in a running stack would count a repeated step.
#[test]
fn a_late_process_gets_the_map_and_the_step_before_the_clock_publishes_it_again() {
    let args = args("late");
    let shutdown = Arc::new(AtomicBool::new(false));
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let clock = {
        let (args, shutdown) = (args.clone(), shutdown.clone());
        std::thread::spawn(move || {
            let mut p = Process::with_shutdown_flag("clock", &args, shutdown).unwrap();
            let cmd = p.trigger(topics::PLANNING_CMD, Order::Newest).unwrap();
            let mut map = p.output(topics::WORLD_MAP).unwrap();
            let mut truth = p.output(topics::WORLD_TRUTH).unwrap();
            // Nobody listens yet: the map and step 0 reach a subscriber only from history.
            map.publish(0, 1, |m| {
                (m.arena_width, m.arena_height, m.dt) = (1.0, 1.0, 0.01);
                (m.grid_resolution, m.robot.radius) = (0.1, 0.1);
            })
            .unwrap();
            ready_tx.send(()).unwrap();
            p.run_clock(cmd, |event| {
                let tick = match event {
                    ClockEvent::Publish { tick }
                    | ClockEvent::Stop { tick }
                    | ClockEvent::Advance { tick, .. } => tick,
                };
                truth.publish(tick, 1, |_| {})?;
                Ok(Flow::Continue)
            })
            .unwrap();
        })
    };
    ready_rx.recv_timeout(Duration::from_secs(10)).unwrap();
    // Let the clock publish step 0 and settle into its wait for the reply.
    std::thread::sleep(Duration::from_millis(200));

    let late =
        Context::with_shutdown_flag("planning", &args, Arc::new(AtomicBool::new(false))).unwrap();
    let mut map = late.subscriber(topics::WORLD_MAP).unwrap();
    let mut truth = late.subscriber(topics::WORLD_TRUTH).unwrap();
    let mut cmd = late.publisher(topics::PLANNING_CMD).unwrap();
    let (mut has_map, mut seen) = (false, Vec::new());
    let give_up = Instant::now() + Duration::from_secs(10);
    while !seen.contains(&1) && Instant::now() < give_up {
        has_map |= map.drain(|_| {}) > 0;
        let mut fresh = Vec::new();
        truth.drain(|t| fresh.push(t.header.tick));
        seen.extend_from_slice(&fresh);
        // Answer each step as planning does, once the map is in.
        if has_map && let Some(&k) = fresh.last() {
            cmd.publish(k, 1, |c| (c.v, c.omega) = (0.0, 0.0)).unwrap();
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    shutdown.store(true, Ordering::SeqCst);
    clock.join().unwrap();
    assert!(
        has_map,
        "the late process was never handed the map (steps seen: {seen:?})"
    );
    assert_eq!(seen, [0, 1], "step 0 handed once, then step 1");
}
