//! The runtime against real iceoryx2 services, in one process: publish in place, wake up,
//! validate, count. Each test uses its own namespace.

use mole_runtime::{ClockMode, CommonArgs, Context, Wake};
use mole_types::topics;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

fn args(test: &str, mode: ClockMode) -> CommonArgs {
    CommonArgs {
        namespace: format!("rt-{test}-{}", std::process::id()),
        mode,
        rate_hz: 100.0,
        seed: None,
    }
}

fn context(role: &str, args: &CommonArgs) -> Context {
    Context::with_shutdown_flag(role, args, Arc::new(AtomicBool::new(false))).expect("context")
}

#[test]
fn a_published_message_wakes_the_subscriber_and_arrives_intact() {
    for mode in [ClockMode::Realtime, ClockMode::Lockstep] {
        let args = args(&format!("wake-{mode}"), mode);
        let mut producer = context("producer", &args);
        let mut consumer = context("consumer", &args);
        let mut cmd_pub = producer.publisher(topics::PLANNING_CMD).unwrap();
        let mut cmd_sub = consumer.subscriber(topics::PLANNING_CMD).unwrap();
        let waitset = consumer.waitset().unwrap();
        let cmd_wake = cmd_sub.waker();
        let _attached = waitset.attach(&cmd_wake).unwrap();

        let origin = mole_runtime::now_ns();
        cmd_pub
            .publish(7, origin, |c| {
                c.v = 0.25;
                c.omega = -0.5;
                c.mode = mole_types::MODE_EXPLORE;
                c._pad = 0;
            })
            .unwrap();
        let wake = waitset
            .wait(&mut consumer, Some(Instant::now() + Duration::from_secs(2)))
            .unwrap();
        assert_eq!(wake, Wake::Data, "{mode}");
        let mut seen = Vec::new();
        assert_eq!(
            cmd_sub.drain(|c| seen.push((c.header.tick, c.v, c.omega))),
            1
        );
        assert_eq!(seen, vec![(7, 0.25, -0.5)]);
        assert_eq!(cmd_sub.tick(), Some(7));
        let header = cmd_sub.latest().unwrap().header;
        assert_eq!(header.origin_ns, origin);
        assert!(header.stamp_ns >= origin);
        // Nothing new: the WaitSet times out instead of spinning.
        let wake = waitset
            .wait(
                &mut consumer,
                Some(Instant::now() + Duration::from_millis(50)),
            )
            .unwrap();
        assert_eq!(wake, Wake::Timeout);
        producer.count_step();
    }
}

#[test]
fn invalid_messages_are_dropped_and_counted() {
    let args = args("invalid", ClockMode::Realtime);
    let producer = context("producer", &args);
    let consumer = context("consumer", &args);
    let mut cmd_pub = producer.publisher(topics::PLANNING_CMD).unwrap();
    let mut cmd_sub = consumer.subscriber(topics::PLANNING_CMD).unwrap();
    cmd_pub
        .publish(1, 0, |c| {
            c.v = f64::NAN;
            c.omega = 0.0;
            c.mode = 0;
        })
        .unwrap();
    cmd_pub
        .publish(2, 0, |c| {
            c.v = 0.1;
            c.omega = 0.0;
            c.mode = 77;
        })
        .unwrap();
    cmd_pub
        .publish(3, 0, |c| {
            c.v = 0.1;
            c.omega = 0.0;
            c.mode = 0;
        })
        .unwrap();
    assert!(cmd_sub.update());
    assert_eq!(cmd_sub.tick(), Some(3), "only the valid message is kept");
    assert!(!cmd_sub.update(), "nothing new");
}

/// Publishes a valid command for each tick, in this order.
fn publish_cmds(cmd_pub: &mut mole_runtime::Publisher<mole_types::Cmd>, ticks: &[u64]) {
    for &tick in ticks {
        cmd_pub
            .publish(tick, 0, |c| {
                c.v = 0.1;
                c.omega = 0.0;
                c.mode = 0;
                c._pad = 0;
            })
            .unwrap();
    }
}

#[test]
fn update_through_holds_back_a_step_that_came_early() {
    let args = args("through", ClockMode::Lockstep);
    let producer = context("producer", &args);
    let consumer = context("consumer", &args);
    let mut cmd_pub = producer.publisher(topics::PLANNING_CMD).unwrap();
    let mut cmd_sub = consumer.subscriber(topics::PLANNING_CMD).unwrap();
    publish_cmds(&mut cmd_pub, &[3, 4, 5]);
    assert!(cmd_sub.update_through(3));
    assert_eq!(cmd_sub.tick(), Some(3), "4 and 5 came early and wait");
    assert!(!cmd_sub.update_through(3), "nothing new up to 3");
    assert!(cmd_sub.update_through(4));
    assert_eq!(cmd_sub.tick(), Some(4));
    // A plain update takes the held-back and queued ones: the newest by tick.
    publish_cmds(&mut cmd_pub, &[6]);
    assert!(cmd_sub.update());
    assert_eq!(cmd_sub.tick(), Some(6));
}

#[test]
fn update_through_finds_the_step_asked_for_behind_another_publishers_early_one() {
    // A hot swap: the old and the new process publish side by side, and iceoryx2 hands out
    // one publisher's queue before the other's.
    let args = args("two-publishers", ClockMode::Lockstep);
    let (old, new) = (context("old", &args), context("new", &args));
    let consumer = context("consumer", &args);
    let mut sub = consumer.subscriber(topics::PLANNING_CMD).unwrap();
    let mut old_pub = old.publisher(topics::PLANNING_CMD).unwrap();
    let mut new_pub = new.publisher(topics::PLANNING_CMD).unwrap();
    for p in [&old_pub, &new_pub] {
        p.update_connections();
    }
    publish_cmds(&mut old_pub, &[5]);
    publish_cmds(&mut new_pub, &[4]);
    publish_cmds(&mut old_pub, &[]);
    assert!(sub.update_through(4));
    assert_eq!(sub.tick(), Some(4), "step 4, whichever queue came first");
    publish_cmds(&mut new_pub, &[5]);
    assert!(sub.update_through(5));
    assert_eq!(sub.tick(), Some(5));
    assert!(!sub.update_through(5), "the second 5 is not news");
}

#[test]
fn update_next_takes_every_step_in_order_and_drops_resends() {
    let args = args("next", ClockMode::Lockstep);
    let producer = context("producer", &args);
    let consumer = context("consumer", &args);
    let mut cmd_pub = producer.publisher(topics::PLANNING_CMD).unwrap();
    let mut cmd_sub = consumer.subscriber(topics::PLANNING_CMD).unwrap();
    assert!(!cmd_sub.update_next(None), "nothing yet");
    publish_cmds(&mut cmd_pub, &[0, 1, 1, 2]);
    assert!(cmd_sub.update_next(None));
    assert_eq!(cmd_sub.tick(), Some(0), "the oldest first, not the newest");
    assert!(
        cmd_sub.update_next(None),
        "a step not handled yet is kept, not skipped"
    );
    assert_eq!(cmd_sub.tick(), Some(0));
    let mut handled = vec![0];
    while cmd_sub.update_next(handled.last().copied()) {
        handled.push(cmd_sub.tick().unwrap());
    }
    assert_eq!(handled, [0, 1, 2], "the resent 1 was dropped");
}

#[test]
fn late_subscribers_get_the_world_map_from_history() {
    let args = args("history", ClockMode::Realtime);
    let producer = context("world", &args);
    let mut map_pub = producer.publisher(topics::WORLD_MAP).unwrap();
    map_pub
        .publish(0, 0, |m| {
            *m = bytemuck::Zeroable::zeroed();
            m.arena_width = 4.0;
            m.arena_height = 3.0;
            m.dt = 0.01;
            m.grid_resolution = 0.1;
            m.robot.radius = 0.2;
        })
        .unwrap();
    let consumer = context("late", &args);
    let mut map_sub = consumer.subscriber(topics::WORLD_MAP).unwrap();
    map_pub.update_connections();
    assert!(map_sub.update());
    assert_eq!(map_sub.latest().unwrap().arena_width, 4.0);
}

#[test]
fn topics_are_discoverable_with_their_type_names() {
    let args = args("discover", ClockMode::Realtime);
    let ctx = context("world", &args);
    let _truth = ctx.publisher(topics::WORLD_TRUTH).unwrap();
    let _scan = ctx.subscriber(topics::SENSING_SCAN).unwrap();
    let listed = mole_runtime::list_topics(&args.namespace);
    assert!(
        listed.contains(&("world/truth".to_string(), "mole.Truth.v1".to_string())),
        "{listed:?}"
    );
    assert!(
        listed.contains(&("sensing/scan".to_string(), "mole.Scan.v1".to_string())),
        "{listed:?}"
    );
    assert!(
        listed.iter().any(|(t, _)| t == "stack/stats"),
        "every context publishes stats"
    );
}

#[test]
fn a_different_layout_on_a_topic_is_refused_naming_both_types() {
    let args = args("mismatch", ClockMode::Realtime);
    let ctx = context("planning", &args);
    let _cmd = ctx.publisher(topics::PLANNING_CMD).unwrap();
    let other = context("rogue", &args);
    let wrong: mole_types::Topic<mole_types::Odom> = mole_types::Topic::new("planning/cmd");
    let Err(err) = other.subscriber(wrong) else {
        panic!("a subscriber of the wrong type was accepted")
    };
    let text = err.to_string();
    assert!(
        text.contains("planning/cmd")
            && text.contains("mole.Cmd.v1")
            && text.contains("mole.Odom.v1"),
        "{text}"
    );
}

#[test]
fn a_lockstep_publisher_gives_up_on_a_subscriber_that_reads_nothing() {
    // In a thread, so that a publisher waiting forever fails the test instead of hanging it.
    let (done, finished) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let args = args("stuck", ClockMode::Lockstep);
        let producer = context("producer", &args);
        let consumer = context("consumer", &args);
        let mut cmd_pub = producer.publisher(topics::PLANNING_CMD).unwrap();
        let mut cmd_sub = consumer.subscriber(topics::PLANNING_CMD).unwrap();
        let buffer = topics::PLANNING_CMD.buffer as u64;
        let ticks: Vec<u64> = (0..buffer).collect();
        publish_cmds(&mut cmd_pub, &ticks);
        // The queue is full and nobody reads it: the next sample waits STUCK_CONSUMER, then
        // is dropped for this subscriber; after a shutdown request it does not wait at all.
        publish_cmds(&mut cmd_pub, &[buffer]);
        producer.request_shutdown();
        publish_cmds(&mut cmd_pub, &[buffer + 1]);
        let mut received = Vec::new();
        cmd_sub.drain(|c| received.push(c.header.tick));
        let _ = done.send(received);
    });
    let received = finished
        .recv_timeout(mole_runtime::STUCK_CONSUMER * 5)
        .expect("the publisher gave up on the full queue");
    let buffer = topics::PLANNING_CMD.buffer as u64;
    assert_eq!(received, (0..buffer).collect::<Vec<_>>());
}
