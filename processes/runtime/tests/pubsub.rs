//! The runtime against real iceoryx2 services, in one process: publish in place, wake up,
//! validate, count. Each test uses its own namespace.

use iceoryx2::prelude::*;
use mole_runtime::{ClockMode, CommonArgs, Context, Wake};
use mole_types::topics;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

fn args(test: &str, mode: ClockMode) -> CommonArgs {
    CommonArgs::attach(&format!("rt-{test}-{}", std::process::id()), mode)
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
            && text.contains("mole.Odom.v2"),
        "{text}"
    );
}

/// Creates `planning/cmd` in `namespace` the way a process in another language does: with
/// iceoryx2's type details written by hand, the type name right, the size and alignment as
/// given, every other setting as the topic constant has it.
fn foreign_cmd_service(
    namespace: &str,
    size: usize,
    alignment: usize,
) -> (
    Node<ipc::Service>,
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<
        ipc::Service,
        [iceoryx2::service::marker::CustomPayloadMarker],
        (),
    >,
) {
    use iceoryx2::service::static_config::message_type_details::{TypeDetail, TypeVariant};
    let topic = topics::PLANNING_CMD;
    let node = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .unwrap();
    let name = topics::service_name(namespace, topic.name);
    let name: ServiceName = name.as_str().try_into().unwrap();
    let layout = TypeDetail::__internal_new_from_parts(
        TypeVariant::FixedSize,
        "mole.Cmd.v1",
        size,
        alignment,
    )
    .unwrap();
    // SAFETY: no port of this service is ever created; it only holds the foreign layout.
    let builder = unsafe {
        node.service_builder(&name)
            .publish_subscribe::<[iceoryx2::service::marker::CustomPayloadMarker]>()
            .__internal_set_payload_type_details(&layout)
    };
    let service = builder
        .history_size(topic.history)
        .subscriber_max_buffer_size(topic.buffer)
        .subscriber_max_borrowed_samples(2)
        .max_publishers(topic.max_publishers)
        .max_subscribers(topic.max_subscribers)
        .enable_safe_overflow(true)
        .create()
        .unwrap();
    (node, service)
}

/// A topic whose layout has our type name but another size or alignment is refused for a
/// subscriber and a publisher, naming the topic, the expected and the found layout.
#[test]
fn the_same_type_name_with_another_size_or_alignment_is_refused() {
    let ours = format!(
        "expected `mole.Cmd.v1` ({} bytes, aligned to {})",
        size_of::<mole_types::Cmd>(),
        align_of::<mole_types::Cmd>()
    );
    let (size, alignment) = (size_of::<mole_types::Cmd>(), align_of::<mole_types::Cmd>());
    let layouts = [
        (size + 8, alignment),
        (size - 8, alignment),
        (size, alignment / 2),
        (size, alignment * 2),
    ];
    for (case, (size, alignment)) in layouts.into_iter().enumerate() {
        let args = args(&format!("layout-{case}"), ClockMode::Realtime);
        let _foreign = foreign_cmd_service(&args.namespace, size, alignment);
        let ctx = context("planning", &args);
        let refusals = [
            ctx.subscriber(topics::PLANNING_CMD).err(),
            ctx.publisher(topics::PLANNING_CMD).err(),
        ];
        for (port, refusal) in ["subscriber", "publisher"].iter().zip(refusals) {
            let found = format!("found `mole.Cmd.v1` ({size} bytes, aligned to {alignment})");
            let Some(err) = refusal else {
                panic!("a {port} accepted `mole.Cmd.v1` of {size} bytes aligned to {alignment}")
            };
            let text = err.to_string();
            assert!(
                text.contains("`planning/cmd`") && text.contains(&ours) && text.contains(&found),
                "{port}: {text}"
            );
        }
    }
}

/// The services and nodes of `namespace` that iceoryx2 still knows, alive or not.
fn leftovers(namespace: &str) -> Vec<String> {
    use iceoryx2::node::NodeView;
    let prefix = format!("mole/{namespace}/");
    let mut names = Vec::new();
    ipc::Service::list(Config::global_config(), |service| {
        let name = service.static_details.name().as_str();
        if name.starts_with(&prefix) {
            names.push(format!("service {name}"));
        }
        CallbackProgression::Continue
    })
    .expect("list the services");
    Node::<ipc::Service>::list(Config::global_config(), |node| {
        let details = match &node {
            NodeState::Alive(view) => view.details(),
            NodeState::Dead(view) => view.details(),
            NodeState::Inaccessible(_) | NodeState::Undefined(_) => &None,
        };
        if let Some(details) = details
            && details.name().as_str().starts_with(&prefix)
        {
            names.push(format!("node {}", details.name().as_str()));
        }
        CallbackProgression::Continue
    })
    .expect("list the nodes");
    names
}

/// A test's worker thread, stopped and joined when the test ends, passed or failed: a
/// shutdown request makes a waiting lockstep publisher drop its sample, so the thread ends
/// and its nodes and services are gone before the test binary exits.
struct Worker {
    shutdown: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.shutdown.store(true, Ordering::SeqCst);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// How long `f` took.
fn timed(f: impl FnOnce()) -> std::time::Duration {
    let start = std::time::Instant::now();
    f();
    start.elapsed()
}

/// A lockstep publisher stops waiting for a full queue after STUCK_CONSUMER or a shutdown,
/// and the test leaves no node or service of its namespace behind.
#[test]
fn a_lockstep_publisher_gives_up_on_a_subscriber_that_reads_nothing() {
    // In a thread, so that a publisher waiting forever fails the test instead of hanging it.
    let args = args("stuck", ClockMode::Lockstep);
    let shutdown = Arc::new(AtomicBool::new(false));
    let (done, finished) = std::sync::mpsc::channel();
    let thread = {
        let (args, shutdown) = (args.clone(), shutdown.clone());
        std::thread::spawn(move || {
            let received = {
                let producer = Context::with_shutdown_flag("producer", &args, shutdown.clone())
                    .expect("context");
                let consumer =
                    Context::with_shutdown_flag("consumer", &args, shutdown).expect("context");
                let mut cmd_pub = producer.publisher(topics::PLANNING_CMD).unwrap();
                let mut cmd_sub = consumer.subscriber(topics::PLANNING_CMD).unwrap();
                let buffer = topics::PLANNING_CMD.buffer as u64;
                let ticks: Vec<u64> = (0..buffer).collect();
                publish_cmds(&mut cmd_pub, &ticks);
                // The queue is full and nobody reads it: the next sample waits
                // STUCK_CONSUMER, then is dropped for this subscriber; after a shutdown
                // request it does not wait at all.
                let waited = timed(|| publish_cmds(&mut cmd_pub, &[buffer]));
                producer.request_shutdown();
                let after_shutdown = timed(|| publish_cmds(&mut cmd_pub, &[buffer + 1]));
                let mut received = Vec::new();
                cmd_sub.drain(|c| received.push(c.header.tick));
                (received, waited, after_shutdown)
            };
            // Every port and node is gone before the test learns the result.
            let _ = done.send(received);
        })
    };
    let worker = Worker {
        shutdown,
        thread: Some(thread),
    };
    let (received, waited, after_shutdown) = finished
        .recv_timeout(mole_runtime::STUCK_CONSUMER * 5)
        .expect("the publisher gave up on the full queue");
    drop(worker);
    let buffer = topics::PLANNING_CMD.buffer as u64;
    assert_eq!(received, (0..buffer).collect::<Vec<_>>());
    // The bound, not a timing target: the stuck sample waited it out, the one after the
    // shutdown request did not wait for it.
    let bound = mole_runtime::STUCK_CONSUMER;
    assert!(
        waited >= bound,
        "gave up after {waited:?}, before {bound:?}"
    );
    assert!(
        after_shutdown < bound,
        "waited {after_shutdown:?} after shutdown"
    );
    assert_eq!(leftovers(&args.namespace), Vec::<String>::new());
}
