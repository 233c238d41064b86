//! The whole process loop allocates nothing per step in steady state beyond what iceoryx2
//! itself allocates: publish (loan, write in place, send, notify), wait (the WaitSet,
//! publishing the statistics on the way) and receive (update, drain), counted by a counting
//! global allocator (this test binary only).

use iceoryx2::prelude::*;
use mole_runtime::{
    ClockMode, CommonArgs, Context, CountingAllocator, Wake, allocations_during, now_ns,
};
use mole_types::{Cmd, topics};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// Steps before counting: ports connect, first statistics go out.
const WARM_UP_STEPS: u64 = 200;

/// Guards against a hang only: the loop runs until both processes published their statistics.
const GIVE_UP_AFTER: Duration = Duration::from_secs(30);

/// Allocations per phase of the loop, summed over the counted steps.
#[derive(Debug, Default, PartialEq)]
struct Tally {
    publish: u64,
    wait: u64,
    receive: u64,
}

/// Allocations of one bare iceoryx2 publish (loan, write, send) of a command, no runtime
/// around it. iceoryx2 0.10 boxes the shared state of every loaned sample (an `Rc` made in
/// `Publisher::loan_uninit`), which no caller can avoid; the runtime may add nothing to it.
fn allocations_of_a_bare_iceoryx2_publish(namespace: &str) -> u64 {
    const SENDS: u64 = 100;
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .unwrap();
    let name: ServiceName = format!("mole/{namespace}/bare")
        .as_str()
        .try_into()
        .unwrap();
    let service = node
        .service_builder(&name)
        .publish_subscribe::<Cmd>()
        .open_or_create()
        .unwrap();
    let publisher = service.publisher_builder().create().unwrap();
    let subscriber = service.subscriber_builder().create().unwrap();
    let send = || {
        let sample = publisher.loan_uninit().unwrap();
        sample
            .write_payload(bytemuck::Zeroable::zeroed())
            .send()
            .unwrap();
    };
    let receive = || while subscriber.receive().unwrap().is_some() {};
    send();
    receive();
    let mut total = 0;
    for _ in 0..SENDS {
        total += allocations_during(send);
        receive();
    }
    assert_eq!(total % SENDS, 0, "{total} allocations in {SENDS} sends");
    total / SENDS
}

fn context(role: &str, args: &CommonArgs) -> Context {
    Context::with_shutdown_flag(role, args, Arc::new(AtomicBool::new(false))).expect("context")
}

/// A closed loop of two processes, statistics included, allocates only what iceoryx2's own
/// loan does, in realtime and in lockstep.
#[test]
fn publish_wait_receive_allocates_nothing_per_step() {
    // A broken counter would pass everything below: it must see this Box first.
    let boxed = allocations_during(|| {
        std::hint::black_box(Box::new([0u8; 64]));
    });
    assert!(boxed >= 1, "a Box was allocated, the counter saw {boxed}");

    for mode in [ClockMode::Realtime, ClockMode::Lockstep] {
        let args = CommonArgs::attach(&format!("rt-no-alloc-{mode}-{}", std::process::id()), mode);
        // Planner and world close the loop: command out, odometry back.
        let mut planner = context("planner", &args);
        let mut world = context("world", &args);
        let monitor = context("monitor", &args);
        let mut cmd_pub = planner.publisher(topics::PLANNING_CMD).unwrap();
        let mut cmd_sub = world.subscriber(topics::PLANNING_CMD).unwrap();
        let mut odom_pub = world.publisher(topics::SENSING_ODOM).unwrap();
        let mut odom_sub = planner.subscriber(topics::SENSING_ODOM).unwrap();
        let mut stats_sub = monitor.passive_subscriber(topics::STACK_STATS).unwrap();
        let (world_ws, planner_ws) = (world.waitset().unwrap(), planner.waitset().unwrap());
        let (cmd_wake, odom_wake) = (cmd_sub.waker(), odom_sub.waker());
        let _cmd_attached = world_ws.attach(&cmd_wake).unwrap();
        let _odom_attached = planner_ws.attach(&odom_wake).unwrap();
        planner.ready();
        world.ready();

        let per_publish = allocations_of_a_bare_iceoryx2_publish(&args.namespace);
        let mut tally = Tally::default();
        let mut step = |tick: u64, tally: &mut Tally| {
            let deadline = Instant::now() + GIVE_UP_AFTER;
            tally.publish += allocations_during(|| {
                cmd_pub
                    .publish(tick, now_ns(), |c| {
                        c.v = 0.2;
                        c.omega = 0.1;
                        c.mode = mole_types::MODE_EXPLORE;
                        c._pad = 0;
                    })
                    .unwrap();
            });
            let mut woke = None;
            tally.wait +=
                allocations_during(|| woke = Some(world_ws.wait(&mut world, Some(deadline))));
            assert_eq!(
                woke.unwrap().unwrap(),
                Wake::Data,
                "{mode} step {tick}: world"
            );
            let mut fresh = false;
            tally.receive += allocations_during(|| fresh = cmd_sub.update());
            assert!(
                fresh && cmd_sub.tick() == Some(tick),
                "{mode} step {tick}: command"
            );

            tally.publish += allocations_during(|| {
                odom_pub
                    .publish(tick, now_ns(), |o| {
                        o.v = 0.2;
                        o.omega = 0.1;
                        o.dt = 0.01;
                    })
                    .unwrap();
            });
            let mut woke = None;
            tally.wait +=
                allocations_during(|| woke = Some(planner_ws.wait(&mut planner, Some(deadline))));
            assert_eq!(
                woke.unwrap().unwrap(),
                Wake::Data,
                "{mode} step {tick}: planner"
            );
            let mut received = 0;
            tally.receive += allocations_during(|| received = odom_sub.drain(|_| {}));
            assert_eq!(received, 1, "{mode} step {tick}: odometry");
            world.count_step();
            planner.count_step();
        };

        for tick in 0..WARM_UP_STEPS {
            step(tick, &mut Tally::default());
        }
        stats_sub.drain(|_| {});
        // Count until each process has published its statistics from inside the loop (once a
        // second), so that publishing them is counted too.
        let (mut planner_stats, mut world_stats) = (0, 0);
        let give_up = Instant::now() + GIVE_UP_AFTER;
        let mut tick = WARM_UP_STEPS;
        while planner_stats == 0 || world_stats == 0 {
            assert!(
                Instant::now() < give_up,
                "{mode}: no statistics after {tick} steps"
            );
            step(tick, &mut tally);
            tick += 1;
            stats_sub.drain(|s| match mole_types::read_name(&s.process).as_ref() {
                "planner" => planner_stats += 1,
                "world" => world_stats += 1,
                _ => {}
            });
        }
        // Two publishes a step, and each statistics sample is published from inside a wait.
        let steps = tick - WARM_UP_STEPS;
        let expected = Tally {
            publish: 2 * steps * per_publish,
            wait: (planner_stats + world_stats) * per_publish,
            receive: 0,
        };
        assert_eq!(
            tally, expected,
            "{mode}: allocations over {steps} steps, iceoryx2 making {per_publish} a publish"
        );
    }
}
