//! The process's node, its ports' factory, its wake-ups and its shutdown.

use crate::clock::ClockMode;
use crate::ports::{Publisher, Subscriber, Waker};
use crate::stats::StatsRegistry;
use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use mole_types::{Message, Stats, Topic, topics};
use nix::poll::{PollFd, PollFlags, PollTimeout};
use std::os::fd::{AsFd, AsRawFd, BorrowedFd, RawFd};
use std::rc::Rc;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How often a process publishes its statistics.
const STATS_PERIOD: Duration = Duration::from_secs(1);

/// What can go wrong in the runtime. Every variant carries a sentence a user can act on.
#[derive(Debug, thiserror::Error)]
pub enum RuntimeError {
    #[error("invalid name `{0}`: {1}")]
    Name(String, String),
    #[error("cannot create the node `{0}`: {1}")]
    Node(String, String),
    #[error("cannot open topic `{topic}`: {reason}")]
    Service { topic: String, reason: String },
    #[error("{0}")]
    Port(String),
    #[error("waiting failed: {0}")]
    Wait(String),
    #[error("cannot install the Ctrl-C handler: {0}")]
    Signal(String),
    #[error("{0}")]
    Setting(String),
}

/// The arguments every process takes, from its command line or the environment the launcher
/// sets (`MOLE_NAMESPACE`, `MOLE_MODE`, `MOLE_RATE_HZ`, `MOLE_SEED`).
#[derive(Debug, Clone, clap::Args)]
pub struct CommonArgs {
    /// Namespace of the stack: services are `mole/<namespace>/<topic>`.
    #[arg(long, env = "MOLE_NAMESPACE", default_value = "robot0")]
    pub namespace: String,
    /// Clock mode: realtime or lockstep.
    #[arg(long, env = "MOLE_MODE", default_value = "realtime")]
    pub mode: ClockMode,
    /// World step rate in realtime mode (Hz).
    #[arg(long, env = "MOLE_RATE_HZ", default_value_t = 100.0)]
    pub rate_hz: f64,
    /// Seed override (the scenario's seed otherwise).
    #[arg(long, env = "MOLE_SEED")]
    pub seed: Option<u64>,
}

/// Input a process refuses (a goal-seeking planner without a goal...): exit code 2, which no
/// restart policy retries.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct BadInput(pub String);

/// The exit code of a process's run: 0 on success, 2 for [`BadInput`] (printed as
/// `error: ...` for the launcher to report), 1 for anything else (logged).
pub fn exit_code(result: Result<(), Box<dyn std::error::Error>>) -> std::process::ExitCode {
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e)
            if e.is::<BadInput>()
                || matches!(
                    e.downcast_ref::<RuntimeError>(),
                    Some(RuntimeError::Setting(_))
                ) =>
        {
            eprintln!("error: {e}");
            std::process::ExitCode::from(2)
        }
        Err(e) => {
            tracing::error!("{e}");
            std::process::ExitCode::FAILURE
        }
    }
}

/// CLOCK_MONOTONIC in nanoseconds: the clock of every `stamp_ns` and `origin_ns`.
pub fn now_ns() -> u64 {
    match nix::time::clock_gettime(nix::time::ClockId::CLOCK_MONOTONIC) {
        Ok(ts) => (ts.tv_sec() as u64).saturating_mul(1_000_000_000) + ts.tv_nsec() as u64,
        Err(_) => 0,
    }
}

/// Logs to stderr through `tracing`, filtered by RUST_LOG (default `info`); iceoryx2's own log
/// shows errors only unless IOX2_LOG_LEVEL says otherwise.
pub fn init_tracing(role: &str) {
    set_iceoryx_log_level();
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .try_init();
    tracing::debug!(role, "tracing initialised");
}

/// iceoryx2's own log shows errors only, unless IOX2_LOG_LEVEL says otherwise.
pub(crate) fn set_iceoryx_log_level() {
    set_log_level_from_env_or(LogLevel::Error);
}

/// The node `mole/<namespace>/<role>`, iceoryx2's signal handling disabled.
pub(crate) fn create_node(namespace: &str, role: &str) -> Result<Node<ipc::Service>, RuntimeError> {
    set_iceoryx_log_level();
    let node_name = format!("mole/{namespace}/{role}");
    let name: NodeName = node_name
        .as_str()
        .try_into()
        .map_err(|e| RuntimeError::Name(node_name.clone(), format!("{e:?}")))?;
    NodeBuilder::new()
        .name(&name)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| RuntimeError::Node(node_name, format!("{e:?}")))
}

/// Removes the resources of every dead node (a crashed earlier run, a killed process), so they
/// never block a new one. Returns how many nodes were cleaned.
pub fn cleanup_dead_nodes() -> usize {
    let mut cleaned = 0;
    let mut failed = 0;
    let result = Node::<ipc::Service>::list(Config::global_config(), |state| {
        if let NodeState::Dead(view) = state {
            let name = view.details().as_ref().map(|d| d.name().to_string());
            match view.try_remove_stale_resources() {
                Ok(()) => {
                    cleaned += 1;
                    tracing::info!(node = ?name, "cleaned the resources of a dead node");
                }
                Err(e) => {
                    failed += 1;
                    tracing::debug!(node = ?name, "cannot clean a dead node: {e:?}");
                }
            }
        }
        CallbackProgression::Continue
    });
    if let Err(e) = result {
        tracing::warn!("cannot list nodes: {e:?}");
    }
    if failed > 0 {
        tracing::warn!(
            failed,
            "dead nodes whose resources iceoryx2 could not clean (RUST_LOG=debug names them)"
        );
    }
    cleaned
}

/// Names of the live nodes of a namespace (`mole/<ns>/<role>`), e.g. to refuse a second stack.
pub fn live_nodes_in_namespace(namespace: &str) -> Vec<String> {
    let prefix = format!("mole/{namespace}/");
    let mut names = Vec::new();
    let _ = Node::<ipc::Service>::list(Config::global_config(), |state| {
        if let NodeState::Alive(view) = state
            && let Some(details) = view.details()
        {
            let name = details.name().to_string();
            if name.starts_with(&prefix) {
                names.push(name);
            }
        }
        CallbackProgression::Continue
    });
    names
}

type PubSubFactory<M> =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, M, ()>;
type EventFactory = iceoryx2::service::port_factory::event::PortFactory<ipc::Service>;

/// The publish-subscribe services of a namespace as iceoryx2 lists them: `(topic, payload type
/// name)`, sorted. Any tool that lists iceoryx2 services (`iox2 service list`) sees the same.
pub fn list_topics(namespace: &str) -> Vec<(String, String)> {
    use iceoryx2::service::Service as _;
    use iceoryx2::service::static_config::messaging_pattern::MessagingPattern;
    let prefix = format!("mole/{namespace}/");
    let mut topics = Vec::new();
    let result = ipc::Service::list(Config::global_config(), |details| {
        let name = details.static_details.name().as_str();
        if let Some(topic) = name.strip_prefix(&prefix)
            && let MessagingPattern::PublishSubscribe(config) =
                details.static_details.messaging_pattern()
        {
            let payload = config
                .message_type_details()
                .payload
                .type_name()
                .to_string();
            topics.push((topic.to_string(), payload));
        }
        CallbackProgression::Continue
    });
    if let Err(e) = result {
        tracing::warn!("cannot list services: {e:?}");
    }
    topics.sort();
    topics
}

/// One process's link to the stack: its node in the namespace, its statistics, its shutdown flag.
pub struct Context {
    node: Node<ipc::Service>,
    namespace: String,
    role: String,
    mode: ClockMode,
    rate_hz: f64,
    seed: Option<u64>,
    shutdown: Arc<AtomicBool>,
    stats: StatsRegistry,
    stats_publisher: Option<Publisher<Stats>>,
    last_stats: Instant,
    steps: u64,
    spin_lead: Duration,
}

/// Lockstep: the longest a process sleeps without looking at its inputs (see
/// [`WaitSet::wait`]); costs ten idle wake-ups a second.
pub const LOCKSTEP_RECHECK: Duration = Duration::from_millis(100);

/// Lockstep: how long a publisher waits for a subscriber whose queue is full before it drops
/// the sample for that subscriber. Far above any real wait (µs to ms), below the launcher's
/// hang detection, so a frozen consumer stalls the stack only until it is restarted.
pub const STUCK_CONSUMER: Duration = Duration::from_secs(3);

/// How long before a realtime input is due a process starts looking for it (µs), unless
/// `MOLE_SPIN_US` says otherwise.
pub const DEFAULT_SPIN_US: u64 = 0;

/// `MOLE_SPIN_US` as a duration.
fn spin_lead_from_env() -> Result<Duration, RuntimeError> {
    match std::env::var("MOLE_SPIN_US") {
        Err(_) => Ok(Duration::from_micros(DEFAULT_SPIN_US)),
        Ok(text) => text
            .trim()
            .parse::<u64>()
            .ok()
            .filter(|us| *us <= 5_000)
            .map(Duration::from_micros)
            .ok_or_else(|| {
                RuntimeError::Setting(format!(
                    "MOLE_SPIN_US: expected microseconds from 0 to 5000, found `{text}`"
                ))
            }),
    }
}

impl Context {
    /// Initialises tracing and the Ctrl-C/SIGTERM handler, cleans dead nodes, and creates the
    /// node `mole/<namespace>/<role>` with iceoryx2's own signal handling disabled.
    pub fn new(role: &str, args: &CommonArgs) -> Result<Context, RuntimeError> {
        init_tracing(role);
        let shutdown = Arc::new(AtomicBool::new(false));
        let flag = shutdown.clone();
        ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
            .map_err(|e| RuntimeError::Signal(e.to_string()))?;
        Self::with_shutdown_flag(role, args, shutdown)
    }

    /// As [`Context::new`], for a process (the launcher) that owns its signal handling.
    pub fn with_shutdown_flag(
        role: &str,
        args: &CommonArgs,
        shutdown: Arc<AtomicBool>,
    ) -> Result<Context, RuntimeError> {
        cleanup_dead_nodes();
        let node = create_node(&args.namespace, role)?;
        let mut ctx = Context {
            node,
            namespace: args.namespace.clone(),
            role: role.to_string(),
            mode: args.mode,
            rate_hz: args.rate_hz,
            seed: args.seed,
            shutdown,
            stats: StatsRegistry::default(),
            stats_publisher: None,
            last_stats: Instant::now(),
            steps: 0,
            spin_lead: spin_lead_from_env()?,
        };
        ctx.stats_publisher = Some(ctx.publisher(topics::STACK_STATS)?);
        Ok(ctx)
    }

    pub fn namespace(&self) -> &str {
        &self.namespace
    }
    pub fn role(&self) -> &str {
        &self.role
    }
    pub fn mode(&self) -> ClockMode {
        self.mode
    }
    pub fn rate_hz(&self) -> f64 {
        self.rate_hz
    }
    /// The `--seed` override, if any.
    pub fn seed(&self) -> Option<u64> {
        self.seed
    }
    /// Keeps `waitset` awake for `trigger`'s next sample (see [`WaitSet::anticipate`]) for
    /// `MOLE_SPIN_US` µs (default [`DEFAULT_SPIN_US`]; 0 turns it off): in realtime from that
    /// long before the sample is due, in lockstep for that long after the last one, since the
    /// next step comes as soon as the stack has gone round once.
    pub fn anticipate(&self, waitset: &WaitSet, trigger: &Waker) {
        let period = match self.mode {
            ClockMode::Realtime if self.rate_hz > 0.0 => {
                Duration::from_secs_f64(1.0 / self.rate_hz)
            }
            ClockMode::Realtime => return,
            ClockMode::Lockstep => Duration::ZERO,
        };
        waitset.anticipate(trigger, period, self.spin_lead);
    }

    /// Whether SIGINT or SIGTERM arrived.
    pub fn shutdown_requested(&self) -> bool {
        self.shutdown.load(Ordering::SeqCst)
    }
    /// Asks the process to stop at its next wake-up.
    pub fn request_shutdown(&self) {
        self.shutdown.store(true, Ordering::SeqCst);
    }
    /// Counts a handled step (reported in the statistics). The first one is announced at once,
    /// so a launcher swapping this process in knows when it has taken over.
    pub fn count_step(&mut self) {
        self.steps += 1;
        if self.steps == 1 {
            self.publish_stats();
        }
    }

    pub(crate) fn node(&self) -> &Node<ipc::Service> {
        &self.node
    }

    fn service_name(&self, topic: &str) -> Result<ServiceName, RuntimeError> {
        let full = topics::service_name(&self.namespace, topic);
        full.as_str()
            .try_into()
            .map_err(|e| RuntimeError::Name(full.clone(), format!("{e:?}")))
    }

    fn open_services<M: Message>(
        &self,
        topic: &Topic<M>,
    ) -> Result<(PubSubFactory<M>, EventFactory), RuntimeError> {
        let name = self.service_name(topic.name)?;
        let failed = |reason: String| RuntimeError::Service {
            topic: topic.name.to_string(),
            reason,
        };
        // Lockstep never drops: a full subscriber queue makes the publisher wait. Realtime
        // drops the oldest sample, so a slow subscriber never stalls the pipeline.
        let lockstep = self.mode == ClockMode::Lockstep;
        let pubsub = self
            .node
            .service_builder(&name)
            .publish_subscribe::<M>()
            .history_size(topic.history)
            .subscriber_max_buffer_size(topic.buffer)
            .subscriber_max_borrowed_samples(2)
            .max_publishers(topic.max_publishers)
            .max_subscribers(topic.max_subscribers)
            .enable_safe_overflow(!lockstep)
            .open_or_create()
            .map_err(|e| {
                failed(describe_open_error(
                    &format!("{e:?}"),
                    &PayloadLayout::of::<M>(),
                    recorded_payload(&name).as_ref(),
                ))
            })?;
        // iceoryx2 opens a service whose payload has our type name and size but a stricter
        // alignment; that is still another layout (another language's definition), so refuse
        // anything but the exact one.
        let ours = PayloadLayout::of::<M>();
        let found = PayloadLayout::recorded(&pubsub.static_config().message_type_details().payload);
        if (found.size, found.alignment) != (ours.size, ours.alignment) {
            return Err(failed(layout_mismatch(&ours, &found)));
        }
        let event = self
            .node
            .service_builder(&name)
            .event()
            .max_notifiers(topic.max_publishers + 2)
            .max_listeners(topic.max_subscribers + 2)
            .open_or_create()
            .map_err(|e| failed(format!("event service: {e:?}")))?;
        Ok((pubsub, event))
    }

    /// A publisher on `topic`, with the event that wakes its subscribers.
    pub fn publisher<M: Message>(&self, topic: Topic<M>) -> Result<Publisher<M>, RuntimeError> {
        let (pubsub, event) = self.open_services(&topic)?;
        let port_failed =
            |e: String| RuntimeError::Port(format!("publisher on {}: {e}", topic.name));
        let lockstep = self.mode == ClockMode::Lockstep;
        let mut builder = pubsub.publisher_builder().max_loaned_samples(2);
        if lockstep {
            // Lockstep waits for a full queue (that is what makes it deterministic), but not
            // forever: a consumer that reads nothing for STUCK_CONSUMER (frozen, or gone while
            // its queue was full) loses this sample instead of stopping the whole stack, and a
            // shutdown never waits.
            let shutdown = self.shutdown.clone();
            let topic_name = topic.name;
            builder = builder
                .backpressure_strategy(BackpressureStrategy::RetryUntilDelivered)
                .set_backpressure_handler(move |info: &iceoryx2::port::BackpressureInfo| {
                    if shutdown.load(Ordering::Relaxed) {
                        return iceoryx2::port::BackpressureAction::DiscardData;
                    }
                    if info.elapsed_time < STUCK_CONSUMER {
                        return iceoryx2::port::BackpressureAction::Retry;
                    }
                    tracing::warn!(
                        topic = topic_name,
                        "a subscriber read nothing for {STUCK_CONSUMER:?}: this sample is dropped for it"
                    );
                    iceoryx2::port::BackpressureAction::DiscardData
                });
        }
        let publisher = builder
            .create()
            .map_err(|e| port_failed(format!("{e:?}")))?;
        let notifier = event
            .notifier_builder()
            .create()
            .map_err(|e| port_failed(format!("{e:?}")))?;
        let stats = self
            .stats
            .register(topic.name, true)
            .map_err(|e| port_failed(format!("{e:?}")))?;
        Ok(Publisher {
            topic: topic.name,
            publisher,
            notifier,
            stats,
            seq: 0,
        })
    }

    /// A subscriber on `topic`, with the listener its WaitSet sleeps on.
    pub fn subscriber<M: Message>(&self, topic: Topic<M>) -> Result<Subscriber<M>, RuntimeError> {
        self.subscriber_with(topic, true)
    }

    /// A subscriber on `topic` that never wakes the process: it is read when another input
    /// wakes it. Publishers do not signal it, which saves them a system call per message; use
    /// it for inputs that arrive before the process's trigger (sensing publishes odom last, so
    /// localization reads the fix and the beacons passively).
    pub fn passive_subscriber<M: Message>(
        &self,
        topic: Topic<M>,
    ) -> Result<Subscriber<M>, RuntimeError> {
        self.subscriber_with(topic, false)
    }

    fn subscriber_with<M: Message>(
        &self,
        topic: Topic<M>,
        wakes: bool,
    ) -> Result<Subscriber<M>, RuntimeError> {
        let (pubsub, event) = self.open_services(&topic)?;
        let port_failed =
            |e: String| RuntimeError::Port(format!("subscriber on {}: {e}", topic.name));
        let subscriber = pubsub
            .subscriber_builder()
            .buffer_size(topic.buffer)
            .create()
            .map_err(|e| port_failed(format!("{e:?}")))?;
        let listener = if wakes {
            let listener = event
                .listener_builder()
                .create()
                .map_err(|e| port_failed(format!("{e:?}")))?;
            Some(Rc::new(listener))
        } else {
            None
        };
        let stats = self
            .stats
            .register(topic.name, false)
            .map_err(|e| port_failed(format!("{e:?}")))?;
        Ok(Subscriber {
            topic: topic.name,
            subscriber: Rc::new(subscriber),
            listener,
            stats,
            latest: None,
            pending: [None, None],
            last_seq: None,
            last_warning: None,
        })
    }

    /// A replacement's hand-over (`mole swap` sets `MOLE_TAKEOVER`): waits up to `grace` for
    /// the process being replaced to publish `topic` (the replacement's own output) and lends
    /// the newest valid sample to `take`; returns its tick, or `None` when none came, and the
    /// replacement starts afresh. The subscriber is gone on return, so the replacement's own
    /// output never fills its queue (a lockstep publisher waits while a queue is full).
    pub fn take_over<M: Message>(
        &mut self,
        topic: Topic<M>,
        grace: Duration,
        take: impl FnOnce(&M),
    ) -> Result<Option<u64>, RuntimeError> {
        let mut predecessor = self.subscriber(topic)?;
        let waitset = self.waitset()?;
        let waker = predecessor.waker();
        let _attached = waitset.attach(&waker)?;
        let deadline = Instant::now() + grace;
        while !predecessor.update() {
            if waitset.wait(self, Some(deadline))? != Wake::Data {
                predecessor.update();
                break;
            }
        }
        Ok(predecessor.latest().map(|m| {
            take(m);
            m.header().tick
        }))
    }

    /// A WaitSet for this process's wake-ups.
    pub fn waitset(&self) -> Result<WaitSet, RuntimeError> {
        Ok(WaitSet {
            sockets: core::cell::RefCell::new(Vec::new()),
            listeners: core::cell::RefCell::new(Vec::new()),
            probes: core::cell::RefCell::new(Vec::new()),
            missed_signal: core::cell::Cell::new(false),
            anticipation: core::cell::RefCell::new(None),
        })
    }

    /// Announces that every port exists: publishes the first statistics at once, which is what
    /// the launcher waits for before starting the processes that depend on this one.
    pub fn ready(&mut self) {
        tracing::info!(role = %self.role, namespace = %self.namespace, mode = %self.mode, "ready");
        self.publish_stats();
    }

    /// Publishes the statistics when their period is due; returns the time until the next.
    pub fn tick_stats(&mut self) -> Duration {
        let elapsed = self.last_stats.elapsed();
        if elapsed >= STATS_PERIOD {
            self.publish_stats();
            STATS_PERIOD
        } else {
            STATS_PERIOD - elapsed
        }
    }

    fn publish_stats(&mut self) {
        let window_s = self.last_stats.elapsed().as_secs_f64();
        self.last_stats = Instant::now();
        let (cpu_ns, max_rss_bytes) = resource_usage();
        let steps = self.steps;
        let (role, registry) = (&self.role, &self.stats);
        if let Some(publisher) = self.stats_publisher.as_mut() {
            let result = publisher.publish(steps, 0, |stats| {
                mole_types::write_name(&mut stats.process, role);
                stats.pid = std::process::id();
                stats.cpu_ns = cpu_ns;
                stats.max_rss_bytes = max_rss_bytes;
                stats.steps = steps;
                registry.write_and_reset_window(stats, window_s);
            });
            if let Err(e) = result {
                tracing::debug!("cannot publish statistics: {e}");
            }
        }
    }
}

/// User + system CPU time (ns) and peak RSS (bytes) of this process.
fn resource_usage() -> (u64, u64) {
    use nix::sys::resource::{UsageWho, getrusage};
    match getrusage(UsageWho::RUSAGE_SELF) {
        Ok(usage) => {
            let tv_ns = |tv: nix::sys::time::TimeVal| {
                (tv.tv_sec() as u64) * 1_000_000_000 + (tv.tv_usec() as u64) * 1000
            };
            let cpu = tv_ns(usage.user_time()) + tv_ns(usage.system_time());
            (cpu, (usage.max_rss() as u64) * 1024)
        }
        Err(_) => (0, 0),
    }
}

/// A payload's layout as iceoryx2 records it for a service: type name, size, alignment.
struct PayloadLayout {
    type_name: String,
    size: usize,
    alignment: usize,
}

impl PayloadLayout {
    /// The layout of this process's message type.
    fn of<M: Message>() -> PayloadLayout {
        PayloadLayout {
            type_name: M::wire_type_name().to_string(),
            size: core::mem::size_of::<M>(),
            alignment: core::mem::align_of::<M>(),
        }
    }

    /// The layout a service records.
    fn recorded(
        detail: &iceoryx2::service::static_config::message_type_details::TypeDetail,
    ) -> PayloadLayout {
        PayloadLayout {
            type_name: detail.type_name().to_string(),
            size: detail.size(),
            alignment: detail.alignment(),
        }
    }
}

impl std::fmt::Display for PayloadLayout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "`{}` ({} bytes, aligned to {})",
            self.type_name, self.size, self.alignment
        )
    }
}

/// The payload layout of the publish-subscribe service `name`, if it exists.
fn recorded_payload(name: &ServiceName) -> Option<PayloadLayout> {
    use iceoryx2::service::static_config::messaging_pattern::MessagingPattern as Recorded;
    let details = ipc::Service::details(
        name,
        Config::global_config(),
        MessagingPattern::PublishSubscribe,
    )
    .ok()??;
    match details.static_details.messaging_pattern() {
        Recorded::PublishSubscribe(config) => Some(PayloadLayout::recorded(
            &config.message_type_details().payload,
        )),
        _ => None,
    }
}

/// The sentence for a topic whose service carries another layout than this process's.
fn layout_mismatch(ours: &PayloadLayout, found: &PayloadLayout) -> String {
    format!(
        "expected {ours}, found {found}: this process and the topic disagree on the message \
         layout; build both sides from the same shared-types"
    )
}

/// Turns iceoryx2's open errors into a sentence; a type mismatch names both layouts.
fn describe_open_error(debug: &str, ours: &PayloadLayout, found: Option<&PayloadLayout>) -> String {
    if debug.contains("IncompatibleTypes") {
        match found {
            Some(found) => layout_mismatch(ours, found),
            None => format!(
                "another process uses a different message type on this topic (this process \
                 speaks {ours})"
            ),
        }
    } else if debug.contains("VersionMismatch") || debug.contains("IncompatibleVersion") {
        "the service was created by a process built against another iceoryx2 version".to_string()
    } else {
        debug.to_string()
    }
}

/// Why a process woke up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Wake {
    /// At least one attached subscriber has new data.
    Data,
    /// The deadline passed with no data.
    Timeout,
    /// SIGINT or SIGTERM arrived: finish up and exit.
    Shutdown,
}

/// Sleeps until data on an attached subscriber, a deadline, or a shutdown.
///
/// It sleeps in poll(2) on the sockets of the attached listeners rather than in iceoryx2's
/// WaitSet, which allocates on every wake-up: a step of a process allocates nothing.
pub struct WaitSet {
    /// What poll(2) watches: the sockets of the attached listeners, kept between waits.
    sockets: core::cell::RefCell<Vec<PollFd<'static>>>,
    /// Every listener ever attached: drained on each wake-up, so a topic the process no longer
    /// reads (world/map after the first sample) cannot keep the WaitSet awake. Holding them
    /// keeps their sockets open for as long as the WaitSet lives.
    listeners: core::cell::RefCell<Vec<Rc<iceoryx2::port::listener::Listener<ipc::Service>>>>,
    /// The queues of the attached subscribers, looked at when a wait ends without a signal.
    probes: core::cell::RefCell<Vec<Rc<dyn crate::ports::Probe>>>,
    /// Whether a sample without its signal was reported already.
    missed_signal: core::cell::Cell<bool>,
    anticipation: core::cell::RefCell<Option<Anticipation>>,
}

/// A periodic input the WaitSet is awake for (see [`WaitSet::anticipate`]).
struct Anticipation {
    trigger: Rc<dyn crate::ports::Probe>,
    period: Duration,
    lead: Duration,
    /// When the trigger's last sample was seen.
    last: core::cell::Cell<Option<Instant>>,
}

impl Anticipation {
    /// The polling window around the trigger's next sample: `lead` before it is due until
    /// `lead / 2` after. A window already past moves on by whole periods.
    fn window(&self, now: Instant) -> Option<(Instant, Instant)> {
        if self.period.is_zero() {
            // Lockstep: the next sample is due as soon as the stack has gone round once.
            let last = self.last.get()?;
            return (now < last + self.lead).then_some((last, last + self.lead));
        }
        let mut due = self.last.get()? + self.period;
        let after = self.lead / 2;
        if now > due + after {
            let late = (now - (due + after)).as_nanos();
            let periods = late / self.period.as_nanos().max(1) + 1;
            due += self.period * u32::try_from(periods).unwrap_or(u32::MAX);
        }
        Some((due.checked_sub(self.lead)?, due + after))
    }
}

/// Keeps a subscriber attached to a [`WaitSet`] while it lives.
pub struct Attachment<'w, 'a> {
    waitset: &'w WaitSet,
    socket: RawFd,
    _waker: core::marker::PhantomData<&'a Waker>,
}

impl Drop for Attachment<'_, '_> {
    fn drop(&mut self) {
        self.waitset
            .sockets
            .borrow_mut()
            .retain(|s| s.as_fd().as_raw_fd() != self.socket);
    }
}

impl WaitSet {
    /// Wakes this WaitSet whenever the waker's topic is published.
    pub fn attach<'w, 'a>(&'w self, waker: &'a Waker) -> Result<Attachment<'w, 'a>, RuntimeError> {
        let Some(listener) = &waker.listener else {
            return Err(RuntimeError::Wait(format!(
                "{} was opened passive: it cannot wake a WaitSet",
                waker.topic
            )));
        };
        // SAFETY: the socket belongs to the listener, which `listeners` keeps alive (and the
        // socket open) for as long as this WaitSet, and so its `sockets`, lives.
        let socket = unsafe { listener.file_descriptor().native_handle() };
        let mut sockets = self.sockets.borrow_mut();
        if sockets.iter().any(|s| s.as_fd().as_raw_fd() == socket) {
            return Err(RuntimeError::Wait(format!(
                "{} is attached already",
                waker.topic
            )));
        }
        // SAFETY: see above; the entry leaves `sockets` when the attachment is dropped.
        let fd = unsafe { BorrowedFd::borrow_raw(socket) };
        sockets.push(PollFd::new(fd, PollFlags::POLLIN));
        self.listeners.borrow_mut().push(listener.clone());
        self.probes.borrow_mut().push(waker.probe.clone());
        Ok(Attachment {
            waitset: self,
            socket,
            _waker: core::marker::PhantomData,
        })
    }

    /// Be awake when `trigger`'s next sample is due instead of paying a wake-up from idle for
    /// it: a realtime input arrives once a `period`, so from `lead` before it is due the
    /// WaitSet looks at the trigger's queue in shared memory (yielding the CPU between looks)
    /// instead of sleeping, until `lead / 2` after; a later sample wakes it as usual. A zero
    /// `period` (lockstep) looks from the last sample until `lead` after it. A zero `lead`
    /// turns it off. Costs about 1.5 × `lead` of CPU per period.
    pub fn anticipate(&self, trigger: &Waker, period: Duration, lead: Duration) {
        *self.anticipation.borrow_mut() = (!lead.is_zero()).then(|| Anticipation {
            trigger: trigger.probe.clone(),
            period,
            lead,
            last: core::cell::Cell::new(None),
        });
    }

    /// Consumes the wake-up signals of every attached listener, on every return: besides
    /// emptying the sockets, `try_wait` resets iceoryx2's "notified" state. In iceoryx2 0.10 a
    /// notification that lands while the listener empties its socket leaves that state set
    /// with no datagram behind; every later notification is then coalesced away and the
    /// WaitSet sleeps through them. Only a `try_wait` clears it again, so a timeout drains too.
    /// (Related upstream report: eclipse-iceoryx/iceoryx2#1811.)
    fn drain_listeners(&self) {
        // Before the caller reads the samples: a sample that arrives after this point leaves
        // its signal pending for the next wait.
        for listener in self.listeners.borrow().iter() {
            let _ = listener.try_wait(|_| {});
        }
    }

    /// Sleeps until data, `deadline` (if any) or a shutdown; publishes the statistics on the
    /// way when they are due.
    pub fn wait(&self, ctx: &mut Context, deadline: Option<Instant>) -> Result<Wake, RuntimeError> {
        // Lockstep never sleeps longer than LOCKSTEP_RECHECK without looking at its inputs: a
        // step whose wake-up went missing costs that long instead of stopping the stack.
        let deadline = match (deadline, ctx.mode()) {
            (None, ClockMode::Lockstep) => Some(Instant::now() + LOCKSTEP_RECHECK),
            (deadline, _) => deadline,
        };
        loop {
            if ctx.shutdown_requested() {
                return Ok(Wake::Shutdown);
            }
            let until_stats = ctx.tick_stats();
            let now = Instant::now();
            let until_deadline = deadline.map(|d| d.saturating_duration_since(now));
            if until_deadline == Some(Duration::ZERO) {
                self.drain_listeners();
                return Ok(Wake::Timeout);
            }
            // poll(2) waits in whole milliseconds: the last fraction of a deadline is slept
            // precisely, so a 100 Hz world ticks on time.
            if let Some(left) = until_deadline
                && left < Duration::from_millis(1)
            {
                std::thread::sleep(left);
                self.drain_listeners();
                return Ok(Wake::Timeout);
            }
            let mut timeout = until_deadline.map_or(until_stats, |d| d.min(until_stats));
            let anticipation = self.anticipation.borrow();
            if let Some(a) = anticipation.as_ref()
                && let Some((from, until)) = a.window(now)
            {
                if now >= from {
                    let end = deadline.map_or(until, |d| d.min(until));
                    while Instant::now() < end && !ctx.shutdown_requested() {
                        if a.trigger.has_data() {
                            a.last.set(Some(Instant::now()));
                            self.drain_listeners();
                            return Ok(Wake::Data);
                        }
                        std::thread::yield_now();
                    }
                    continue;
                }
                // poll(2) waits in whole milliseconds: sleep the last fraction precisely, or
                // the window would open up to 1 ms late.
                let until_from = from - now;
                if until_from <= Duration::from_millis(1) {
                    drop(anticipation);
                    std::thread::sleep(until_from);
                    continue;
                }
                timeout = timeout.min(Duration::from_millis(until_from.as_millis() as u64));
            }
            drop(anticipation);
            let timeout =
                PollTimeout::try_from(timeout.as_millis().max(1)).unwrap_or(PollTimeout::MAX);
            let woke = match nix::poll::poll(&mut self.sockets.borrow_mut(), timeout) {
                Ok(ready) => ready > 0,
                Err(nix::errno::Errno::EINTR) if ctx.shutdown_requested() => {
                    return Ok(Wake::Shutdown);
                }
                Err(nix::errno::Errno::EINTR) => false,
                Err(e) => return Err(RuntimeError::Wait(e.desc().to_string())),
            };
            if woke {
                if let Some(a) = self.anticipation.borrow().as_ref()
                    && a.trigger.has_data()
                {
                    a.last.set(Some(Instant::now()));
                }
                self.drain_listeners();
                return Ok(Wake::Data);
            }
            // No signal: reset a stuck "notified" state (see `drain_listeners`), and if a
            // sample came without its signal, wake up for it now.
            self.drain_listeners();
            if self.probes.borrow().iter().any(|p| p.has_data()) {
                if !self.missed_signal.replace(true) {
                    tracing::warn!(
                        "a sample came without its wake-up signal; found by looking (warned once)"
                    );
                }
                return Ok(Wake::Data);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Never;
    impl crate::ports::Probe for Never {
        fn has_data(&self) -> bool {
            false
        }
    }

    fn anticipation(lead_us: u64) -> Anticipation {
        anticipation_every(Duration::from_millis(10), lead_us)
    }

    fn anticipation_every(period: Duration, lead_us: u64) -> Anticipation {
        Anticipation {
            trigger: Rc::new(Never),
            period,
            lead: Duration::from_micros(lead_us),
            last: core::cell::Cell::new(None),
        }
    }

    #[test]
    fn the_window_opens_lead_before_the_next_sample_and_moves_on_by_whole_periods() {
        let a = anticipation(200);
        let t0 = Instant::now();
        assert_eq!(
            a.window(t0),
            None,
            "nothing seen yet, nothing to anticipate"
        );
        a.last.set(Some(t0));
        let ms = Duration::from_millis;
        let us = Duration::from_micros;
        assert_eq!(
            a.window(t0 + ms(3)),
            Some((t0 + ms(10) - us(200), t0 + ms(10) + us(100)))
        );
        // Inside the window it stays put; past it, the next period's window comes.
        assert_eq!(
            a.window(t0 + ms(10)).map(|w| w.0),
            Some(t0 + ms(10) - us(200))
        );
        assert_eq!(
            a.window(t0 + ms(10) + us(101)).map(|w| w.0),
            Some(t0 + ms(20) - us(200))
        );
        assert_eq!(
            a.window(t0 + ms(35)).map(|w| w.0),
            Some(t0 + ms(40) - us(200)),
            "three periods without the trigger"
        );
    }

    #[test]
    fn in_lockstep_the_window_follows_the_last_sample() {
        let a = anticipation_every(Duration::ZERO, 300);
        let t0 = Instant::now();
        let us = Duration::from_micros;
        assert_eq!(a.window(t0), None, "nothing seen yet");
        a.last.set(Some(t0));
        assert_eq!(a.window(t0 + us(100)), Some((t0, t0 + us(300))));
        assert_eq!(a.window(t0 + us(300)), None, "then it sleeps until woken");
    }
}
