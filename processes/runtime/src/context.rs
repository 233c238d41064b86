//! The process's node, its ports' factory and its shutdown flag.

use crate::admin::create_node;
use crate::clock::ClockMode;
use crate::doorbell::{Doorbell, LISTENER_NAME};
use crate::error::{BadInput, RuntimeError};
use crate::faults::FaultBoard;
use crate::ports::{Publisher, Queue, Subscriber};
use crate::stats::StatsRegistry;
use crate::time::init_tracing;
use crate::waitset::{WaitSet, Wake};
use iceoryx2::prelude::*;
use mole_types::Role;
use mole_types::{Message, Stats, Topic, env, topics};
use std::rc::Rc;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How often a process publishes its statistics.
const STATS_PERIOD: Duration = Duration::from_secs(1);

/// The topic whose publication closes the loop's step: the command, the world's one input from
/// the loop in the graph (`mole_types::graph`; the other, operator/pace, comes from outside the
/// stack). Realtime processes beside the loop wake on it.
const LOOP_CLOSE: Topic<mole_types::Cmd> = topics::PLANNING_CMD;

/// The arguments every process takes, from its command line or the environment the launcher
/// sets (`mole_types::env`).
#[derive(Debug, Clone, clap::Args)]
pub struct CommonArgs {
    /// Namespace of the stack: services are `mole/<namespace>/<topic>`.
    #[arg(long, env = env::NAMESPACE, default_value = env::DEFAULT_NAMESPACE)]
    pub namespace: String,
    /// Clock mode: realtime or lockstep.
    #[arg(long, env = env::MODE, default_value = "realtime")]
    pub mode: ClockMode,
    /// World step rate in realtime mode (Hz).
    #[arg(long, env = env::RATE_HZ, default_value_t = 100.0)]
    pub rate_hz: f64,
    /// Seed override (the scenario's seed otherwise).
    #[arg(long, env = env::SEED)]
    pub seed: Option<u64>,
    /// Go on from the last output of the process this one replaces (set by the launcher on a
    /// swap).
    #[arg(long, env = env::TAKEOVER, default_value_t = false)]
    pub takeover: bool,
    /// Go on from the last outputs, kept in this directory, of the process this one restarts
    /// after a crash (set by the launcher on a restart).
    #[arg(long, env = env::RESUME)]
    pub resume: Option<std::path::PathBuf>,
    /// The role's settings as JSON (docs/settings.md): its `[ROLE.…]` tables of the launch
    /// file and `mole up --set`, as the launcher checked them; unset, the defaults.
    #[arg(long, env = env::SETTINGS)]
    pub settings: Option<String>,
}

impl CommonArgs {
    /// The arguments of a program that attaches to a running stack of clock `mode` to watch or
    /// steer it (a tool, a test): no seed, no takeover, nothing to resume.
    pub fn attach(namespace: &str, mode: ClockMode) -> CommonArgs {
        CommonArgs {
            namespace: namespace.to_string(),
            mode,
            rate_hz: 100.0,
            seed: None,
            takeover: false,
            resume: None,
            settings: None,
        }
    }

    /// The settings of `role` (its table of `--settings`), `S::default()` where they are left
    /// out; JSON that does not parse, or a value out of its bounds, is bad input (exit 2)
    /// naming the key.
    pub fn settings<S: mole_types::settings::Settings>(&self, role: Role) -> Result<S, BadInput> {
        let Some(text) = self.settings.as_deref().filter(|t| !t.trim().is_empty()) else {
            return Ok(S::default());
        };
        let bad = |e: &dyn std::fmt::Display| {
            BadInput(format!(
                "--settings ({}), table `{role}`: {e}",
                env::SETTINGS
            ))
        };
        let mut all: serde_json::Value = serde_json::from_str(text).map_err(|e| bad(&e))?;
        let Some(mine) = all.get_mut(role.name()).map(serde_json::Value::take) else {
            return Ok(S::default());
        };
        let settings: S = serde_json::from_value(mine).map_err(|e| bad(&e))?;
        settings.check().map_err(|e| bad(&e.below(role.name())))?;
        Ok(settings)
    }
}

type PubSubFactory<M> =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, M, ()>;
type EventFactory = iceoryx2::service::port_factory::event::PortFactory<ipc::Service>;

/// One process's link to the stack: its node in the namespace, its statistics, its shutdown flag.
pub struct Context {
    wire: Wire,
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
    /// CPU time spent in step functions (`Context::timed_step`), ns.
    step_cpu_ns: u64,
    takeover: bool,
    resume: Option<std::path::PathBuf>,
    /// This process's publishers (those still alive), for [`Context::offer_history`].
    history_offers: std::cell::RefCell<Vec<std::rc::Weak<dyn crate::ports::OfferHistory>>>,
    /// `stack/faults` as this process's publishers see it, opened with the first of them.
    faults: std::cell::OnceCell<Rc<FaultBoard>>,
}

/// What a context's ports run on.
pub(crate) enum Wire {
    /// iceoryx2: the node, and the doorbell that wakes this node's WaitSets (every mole
    /// publisher of a topic it listens to rings it).
    Ipc {
        node: Node<ipc::Service>,
        doorbell: Rc<Doorbell>,
    },
    /// A test's harness (`harness.rs`): queues in this process.
    Bench(Rc<crate::harness::Bench>),
}

/// Lockstep: how long a publisher waits for a subscriber whose queue is full before it drops
/// the sample for that subscriber. Far above any real wait (µs to ms), below the launcher's
/// hang detection, so a frozen consumer stalls the stack only until it is restarted.
pub const STUCK_CONSUMER: Duration = Duration::from_secs(3);

impl Context {
    /// Initialises tracing and the Ctrl-C/SIGTERM handler and creates the node
    /// `mole/<namespace>/<role>` with iceoryx2's own signal handling disabled. It does not sweep
    /// dead nodes: the launcher does, before it starts the processes and after one dies, so a
    /// process killed while starting is never one killed while cleaning up after others.
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
        let node = create_node(&args.namespace, role)?;
        let doorbell = Rc::new(Doorbell::create(node.id().value())?);
        let wire = Wire::Ipc { node, doorbell };
        let mut ctx = Context::on_wire(wire, role, args, shutdown, StatsRegistry::default());
        ctx.stats_publisher = Some(ctx.publisher(topics::STACK_STATS)?);
        Ok(ctx)
    }

    pub(crate) fn on_wire(
        wire: Wire,
        role: &str,
        args: &CommonArgs,
        shutdown: Arc<AtomicBool>,
        stats: StatsRegistry,
    ) -> Context {
        Context {
            wire,
            namespace: args.namespace.clone(),
            role: role.to_string(),
            mode: args.mode,
            rate_hz: args.rate_hz,
            seed: args.seed,
            shutdown,
            stats,
            stats_publisher: None,
            last_stats: Instant::now(),
            steps: 0,
            step_cpu_ns: 0,
            takeover: args.takeover,
            resume: args.resume.clone(),
            history_offers: Default::default(),
            faults: Default::default(),
        }
    }

    /// The harness this context's ports run on, if it is a test's.
    pub(crate) fn bench(&self) -> Option<&Rc<crate::harness::Bench>> {
        match &self.wire {
            Wire::Bench(bench) => Some(bench),
            Wire::Ipc { .. } => None,
        }
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
    /// Whether this process replaces (or restarts in place of) one that ran before it, and
    /// should go on from that one's last output (`MOLE_TAKEOVER`, set by the launcher).
    pub fn takes_over(&self) -> bool {
        self.takeover
    }
    /// Where the launcher kept the last outputs of the process this one restarts after a crash
    /// (`MOLE_RESUME`).
    pub fn resume_dir(&self) -> Option<&std::path::Path> {
        self.resume.as_deref()
    }
    /// Hands every publisher's history to the subscribers that joined since it last sent, and
    /// wakes them. A lockstep process calls it while it waits: a process restarted after a
    /// crash missed the step that was sent while it was down, and the one that sent it has
    /// nothing new to send until that step is answered; the history (one sample, see the topic
    /// table) is that step.
    pub fn offer_history(&self) {
        let mut offers = self.history_offers.borrow_mut();
        offers.retain(|offer| match offer.upgrade() {
            Some(publisher) => {
                publisher.update_connections();
                true
            }
            None => false,
        });
    }
    /// Publishes no statistics from now on (a helper of the launcher, not a role).
    pub fn silence_stats(&mut self) {
        self.stats_publisher = None;
    }
    /// Whether SIGINT or SIGTERM arrived.
    pub fn shutdown_requested(&self) -> bool {
        self.shutdown.load(Ordering::SeqCst)
    }
    /// Asks the process to stop at its next wake-up.
    pub fn request_shutdown(&self) {
        self.shutdown.store(true, Ordering::SeqCst);
    }
    /// Runs one step's work, `f`, and adds the CPU time this thread spent in it to the
    /// statistics' `step_cpu_ns` (the step function, apart from the runtime around it).
    pub fn timed_step<T>(&mut self, f: impl FnOnce() -> T) -> T {
        let start = thread_cpu_ns();
        let out = f();
        self.add_step_cpu(start);
        out
    }

    /// Adds the CPU time this thread spent since `start` (a [`thread_cpu_ns`] reading) to the
    /// statistics' `step_cpu_ns`, for a step whose work borrows the process.
    pub(crate) fn add_step_cpu(&mut self, start: u64) {
        self.step_cpu_ns += thread_cpu_ns().saturating_sub(start);
    }

    /// Counts a handled step (reported in the statistics). The first one is announced at once,
    /// so a launcher swapping this process in knows when it has taken over.
    pub fn count_step(&mut self) {
        self.steps += 1;
        if self.steps == 1 {
            self.publish_stats();
        }
    }

    pub(crate) fn node(&self) -> Result<&Node<ipc::Service>, RuntimeError> {
        match &self.wire {
            Wire::Ipc { node, .. } => Ok(node),
            Wire::Bench(_) => Err(RuntimeError::Setting(
                "a process on a test harness has no iceoryx2 node".into(),
            )),
        }
    }

    /// `mole/<namespace>/<topic>` as an iceoryx2 service name.
    fn service_name(namespace: &str, topic: &str) -> Result<ServiceName, RuntimeError> {
        let full = topics::service_name(namespace, topic);
        full.as_str()
            .try_into()
            .map_err(|e| RuntimeError::Name(full.clone(), format!("{e:?}")))
    }

    /// The publish-subscribe service `mole/<namespace>/<topic>`, with the exact payload layout
    /// of `M`. `offer`: a topic offered to peers, whose queues drop their oldest sample in every
    /// clock mode; the others drop it in realtime and make the publisher wait in lockstep.
    fn open_pubsub<M: Message>(
        &self,
        namespace: &str,
        topic: &Topic<M>,
        offer: bool,
    ) -> Result<PubSubFactory<M>, RuntimeError> {
        let name = Self::service_name(namespace, topic.name)?;
        let failed = |reason: String| RuntimeError::Service {
            topic: match offer {
                true => topics::service_name(namespace, topic.name),
                false => topic.name.to_string(),
            },
            reason,
        };
        // Lockstep never drops: a full subscriber queue makes the publisher wait. Realtime
        // drops the oldest sample, so a slow subscriber never stalls the pipeline.
        let safe_overflow = offer || topic.never_waits || self.mode != ClockMode::Lockstep;
        let pubsub = self
            .node()?
            .service_builder(&name)
            .publish_subscribe::<M>()
            .history_size(topic.history)
            .subscriber_max_buffer_size(topic.buffer)
            .subscriber_max_borrowed_samples(2)
            .max_publishers(topic.max_publishers)
            .max_subscribers(topic.max_subscribers)
            .enable_safe_overflow(safe_overflow)
            .open_or_create()
            .map_err(|e| {
                let debug = format!("{e:?}");
                failed(if offer && debug.contains("IncompatibleOverflowBehavior") {
                    "it is an ordinary topic of that stack, whose full queue makes its publisher \
                     wait in lockstep; a peer reads only what a robot offers to peers"
                        .to_string()
                } else {
                    describe_open_error(
                        &debug,
                        &PayloadLayout::of::<M>(),
                        recorded_payload(&name).as_ref(),
                    )
                })
            })?;
        // iceoryx2 opens a service whose payload has our type name and size but a stricter
        // alignment; that is still another layout (another language's definition), so refuse
        // anything but the exact one.
        let ours = PayloadLayout::of::<M>();
        let found = PayloadLayout::recorded(&pubsub.static_config().message_type_details().payload);
        if (found.size, found.alignment) != (ours.size, ours.alignment) {
            return Err(failed(layout_mismatch(&ours, &found)));
        }
        Ok(pubsub)
    }

    /// The event service that wakes the subscribers of `mole/<namespace>/<topic>`.
    fn open_event<M: Message>(
        &self,
        namespace: &str,
        topic: &Topic<M>,
    ) -> Result<EventFactory, RuntimeError> {
        let name = Self::service_name(namespace, topic.name)?;
        self.node()?
            .service_builder(&name)
            .event()
            .max_notifiers(topic.max_publishers + 2)
            .max_listeners(topic.max_subscribers + 2)
            .open_or_create()
            .map_err(|e| RuntimeError::Service {
                topic: topic.name.to_string(),
                reason: format!("event service: {e:?}"),
            })
    }

    /// A publisher on `pubsub`, with the notifier of `event`. `waits`: for a full queue, as a
    /// lockstep publisher does.
    fn publisher_on<M: Message>(
        &self,
        topic: &Topic<M>,
        pubsub: PubSubFactory<M>,
        event: EventFactory,
        waits: bool,
    ) -> Result<Publisher<M>, RuntimeError> {
        let port_failed =
            |e: String| RuntimeError::Port(format!("publisher on {}: {e}", topic.name));
        let mut builder = pubsub.publisher_builder().max_loaned_samples(2);
        if waits {
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
        let faults = (self.fault_board()?, self.mode == ClockMode::Lockstep);
        Ok(Publisher::new(
            topic.name,
            publisher,
            notifier,
            stats,
            Some(faults),
        ))
    }

    /// The process's view of `stack/faults`, which every publisher consults before it sends; its
    /// subscriber's statistics are its own (they would crowd out the process's topics).
    fn fault_board(&self) -> Result<Rc<FaultBoard>, RuntimeError> {
        if let Some(board) = self.faults.get() {
            return Ok(board.clone());
        }
        let topic = topics::STACK_FAULTS;
        let pubsub = self.open_pubsub(&self.namespace, &topic, false)?;
        let subscriber = self.subscriber_on(&topic, pubsub, None, &StatsRegistry::default())?;
        Ok(self
            .faults
            .get_or_init(|| Rc::new(FaultBoard::new(subscriber)))
            .clone())
    }

    /// A subscriber on `pubsub`; it wakes the process through a listener on `event` if given.
    fn subscriber_on<M: Message>(
        &self,
        topic: &Topic<M>,
        pubsub: PubSubFactory<M>,
        event: Option<EventFactory>,
        stats: &StatsRegistry,
    ) -> Result<Subscriber<M>, RuntimeError> {
        let port_failed =
            |e: String| RuntimeError::Port(format!("subscriber on {}: {e}", topic.name));
        let subscriber = pubsub
            .subscriber_builder()
            .buffer_size(topic.buffer)
            .create()
            .map_err(|e| port_failed(format!("{e:?}")))?;
        let listener = match event {
            Some(event) => Some(Rc::new(
                event
                    .listener_builder()
                    .name(&listener_name()?)
                    .create()
                    .map_err(|e| port_failed(format!("{e:?}")))?,
            )),
            None => None,
        };
        let stats = stats
            .register(topic.name, false)
            .map_err(|e| port_failed(format!("{e:?}")))?;
        Ok(Subscriber::new(
            topic.name,
            Queue::Shm(Rc::new(subscriber)),
            listener,
            stats,
        ))
    }

    /// A publisher on a harness: what it sends is kept for the test.
    fn bench_publisher<M: Message>(
        &self,
        bench: &Rc<crate::harness::Bench>,
        topic: &Topic<M>,
    ) -> Result<Publisher<M>, RuntimeError> {
        let stats = self
            .stats
            .register(topic.name, true)
            .map_err(|e| RuntimeError::Port(format!("publisher on {}: {e:?}", topic.name)))?;
        Ok(Publisher::on_bench(topic.name, bench.clone(), stats))
    }

    /// A subscriber on a harness: it reads what the test delivers.
    fn bench_subscriber<M: Message>(
        &self,
        bench: &Rc<crate::harness::Bench>,
        topic: &Topic<M>,
    ) -> Result<Subscriber<M>, RuntimeError> {
        let stats = self
            .stats
            .register(topic.name, false)
            .map_err(|e| RuntimeError::Port(format!("subscriber on {}: {e:?}", topic.name)))?;
        let queue = Queue::Fed(bench.inbox(topic.name));
        Ok(Subscriber::new(topic.name, queue, None, stats))
    }

    /// A publisher on `topic`, with the event that wakes its subscribers.
    pub fn publisher<M: Message>(&self, topic: Topic<M>) -> Result<Publisher<M>, RuntimeError> {
        if let Some(bench) = self.bench() {
            return self.bench_publisher(bench, &topic);
        }
        let pubsub = self.open_pubsub(&self.namespace, &topic, false)?;
        let event = self.open_event(&self.namespace, &topic)?;
        let waits = self.mode == ClockMode::Lockstep && !topic.never_waits;
        let publisher = self.publisher_on(&topic, pubsub, event, waits)?;
        self.history_offers
            .borrow_mut()
            .push(publisher.history_offer());
        Ok(publisher)
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
        if let Some(bench) = self.bench() {
            return self.bench_subscriber(bench, &topic);
        }
        let pubsub = self.open_pubsub(&self.namespace, &topic, false)?;
        let event = self.open_event(&self.namespace, &topic)?;
        self.subscriber_on(&topic, pubsub, wakes.then_some(event), &self.stats)
    }

    /// A waker for the close of the loop's step: the listener of the topic that closes it, the
    /// command the world steps on (its one input in the graph), without a subscriber. `pending` is
    /// what the WaitSet looks at when a wait ends without a signal.
    pub(crate) fn loop_closed_waker(
        &self,
        pending: Rc<dyn crate::ports::Pending>,
    ) -> Result<crate::ports::Waker, RuntimeError> {
        let topic = LOOP_CLOSE;
        if self.bench().is_some() {
            return Ok(crate::ports::Waker {
                topic: topic.name,
                listener: None,
                pending,
            });
        }
        let listener = self
            .open_event(&self.namespace, &topic)?
            .listener_builder()
            .name(&listener_name()?)
            .create()
            .map_err(|e| RuntimeError::Port(format!("listener on {}: {e:?}", topic.name)))?;
        Ok(crate::ports::Waker {
            topic: topic.name,
            listener: Some(Rc::new(listener)),
            pending,
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
        Ok(match &self.wire {
            Wire::Ipc { doorbell, .. } => WaitSet::new(doorbell.clone()),
            Wire::Bench(bench) => WaitSet::on_bench(bench.clone()),
        })
    }

    /// A handle that wakes this node's WaitSet from another thread.
    pub fn ringer(&self) -> Result<crate::doorbell::Ringer, RuntimeError> {
        match &self.wire {
            Wire::Ipc { doorbell, .. } => doorbell.ringer(),
            Wire::Bench(_) => Err(RuntimeError::Wait(
                "a process on a test harness has no doorbell".into(),
            )),
        }
    }

    /// The read end of this node's doorbell, for tests that take a ring behind the WaitSet's
    /// back.
    #[doc(hidden)]
    pub fn doorbell_fd(&self) -> std::os::fd::BorrowedFd<'_> {
        match &self.wire {
            Wire::Ipc { doorbell, .. } => doorbell.fd(),
            Wire::Bench(_) => panic!("a process on a test harness has no doorbell"),
        }
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
        let (cpu_ns, system_ns, max_rss_bytes) = resource_usage();
        let (steps, step_cpu_ns) = (self.steps, self.step_cpu_ns);
        let (role, registry) = (&self.role, &self.stats);
        if let Some(publisher) = self.stats_publisher.as_mut() {
            let result = publisher.publish(steps, 0, |stats| {
                mole_types::write_name(&mut stats.process, role);
                stats.pid = std::process::id();
                stats.cpu_ns = cpu_ns;
                stats.max_rss_bytes = max_rss_bytes;
                stats.steps = steps;
                stats.step_cpu_ns = step_cpu_ns;
                stats.system_ns = system_ns;
                registry.write_and_reset_window(stats, window_s);
            });
            if let Err(e) = result {
                tracing::debug!("cannot publish statistics: {e}");
            }
        }
    }
}

/// A process that ends (its run is over, or a SIGTERM asked it to stop) publishes its
/// statistics once more, so that the launcher counts every step it handled and the CPU it took
/// (a short run would otherwise be known only by its first report). Nothing for a process with
/// its statistics silenced.
impl Drop for Context {
    fn drop(&mut self) {
        self.publish_stats();
    }
}

/// The port name of a listener that wakes a mole node: publishers ring the node's doorbell.
fn listener_name() -> Result<iceoryx2::port::port_name::PortName, RuntimeError> {
    iceoryx2::port::port_name::PortName::new(LISTENER_NAME)
        .map_err(|e| RuntimeError::Name(LISTENER_NAME.to_string(), format!("{e:?}")))
}

/// CPU time of the calling thread (ns): user and system, from the kernel's scheduler.
pub(crate) fn thread_cpu_ns() -> u64 {
    use nix::time::{ClockId, clock_gettime};
    clock_gettime(ClockId::CLOCK_THREAD_CPUTIME_ID).map_or(0, |t| {
        t.tv_sec() as u64 * 1_000_000_000 + t.tv_nsec() as u64
    })
}

/// User + system CPU time (ns), system CPU time (ns) and peak RSS (bytes) of this process.
fn resource_usage() -> (u64, u64, u64) {
    use nix::sys::resource::{UsageWho, getrusage};
    match getrusage(UsageWho::RUSAGE_SELF) {
        Ok(usage) => {
            let tv_ns = |tv: nix::sys::time::TimeVal| {
                (tv.tv_sec() as u64) * 1_000_000_000 + (tv.tv_usec() as u64) * 1000
            };
            let system = tv_ns(usage.system_time());
            let cpu = tv_ns(usage.user_time()) + system;
            (cpu, system, (usage.max_rss() as u64) * 1024)
        }
        Err(_) => (0, 0, 0),
    }
}

/// A payload's layout as iceoryx2 records it for a service: type name, size, alignment.
pub struct PayloadLayout {
    pub type_name: String,
    pub size: usize,
    pub alignment: usize,
}

impl PayloadLayout {
    /// The layout of this process's message type.
    pub fn of<M: Message>() -> PayloadLayout {
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

/// The sentence for a topic whose service (or a bridge's peer) carries another layout than this
/// process's.
pub fn layout_mismatch(ours: &PayloadLayout, found: &dyn std::fmt::Display) -> String {
    format!(
        "expected {ours}, found {found}: this process and the topic disagree on the message \
         layout; build both sides from the same shared-types"
    )
}

/// Turns iceoryx2's open errors into a sentence; a type mismatch names both layouts.
fn describe_open_error(debug: &str, ours: &PayloadLayout, found: Option<&PayloadLayout>) -> String {
    if debug.contains("IncompatibleTypes") {
        match found {
            Some(found) => layout_mismatch(ours, &found),
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

/// Ports between robots: a robot offers a topic to other robots' stacks (other namespaces on
/// the same machine) and they read it. The offer's queues drop their oldest sample when full, in
/// lockstep too, so neither robot's loop ever waits for the other's: each runs its own clock.
impl Context {
    /// A publisher offering `topic` to other robots, as `mole/<namespace>/<topic>`. Unlike
    /// [`Context::publisher`] it never waits for a full queue, whatever the clock mode: a reader
    /// in another robot that is slower, not stepping yet, finished or frozen loses its oldest
    /// sample instead of holding this robot back.
    pub fn peer_publisher<M: Message>(
        &self,
        topic: Topic<M>,
    ) -> Result<Publisher<M>, RuntimeError> {
        if let Some(bench) = self.bench() {
            return self.bench_publisher(bench, &topic);
        }
        let pubsub = self.open_pubsub(&self.namespace, &topic, true)?;
        let event = self.open_event(&self.namespace, &topic)?;
        self.publisher_on(&topic, pubsub, event, false)
    }

    /// A passive subscriber on `topic` as the robot in namespace `peer` offers it
    /// ([`Context::peer_publisher`]): it never wakes this process, and its queue can never hold
    /// the peer back. It may come before the peer's stack does; it reads nothing until then.
    /// Refused for this robot's own namespace (a peer is another robot) and for a topic the peer
    /// publishes as an ordinary lockstep topic, whose full queue would make the peer wait.
    pub fn peer_subscriber<M: Message>(
        &self,
        peer: &str,
        topic: Topic<M>,
    ) -> Result<Subscriber<M>, RuntimeError> {
        if peer == self.namespace {
            return Err(RuntimeError::Setting(format!(
                "peer `{peer}` is this robot's own namespace: a peer is another robot's stack"
            )));
        }
        if let Some(bench) = self.bench() {
            return self.bench_subscriber(bench, &topic);
        }
        let pubsub = self.open_pubsub(peer, &topic, true)?;
        self.subscriber_on(&topic, pubsub, None, &self.stats)
    }
}

#[cfg(test)]
mod tests {
    /// The topic the realtime processes beside the loop wake on is the world's one input from
    /// the loop, the command that closes the loop's step; its other input is the operator's.
    #[test]
    fn the_loop_closes_with_the_worlds_one_input_from_the_loop() {
        assert_eq!(
            mole_types::Role::World.spec().inputs,
            &[
                super::LOOP_CLOSE.name,
                mole_types::topics::OPERATOR_PACE.name
            ]
        );
    }
}
