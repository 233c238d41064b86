//! The step loop every process of the control loop runs.
//!
//! A process declares its inputs, each with a [`Rule`] that says which of the topic's samples a
//! step uses, and its outputs; the runtime waits, receives `world/map` once, decides when a step
//! is due in either clock mode, joins a run already under way, hands a replacement the last
//! output of the process it replaces, and counts the steps. The process supplies the algorithm:
//! `init` (once, from the map) and `step` (once per step).
//!
//! ```text
//! let mut p = Process::new(Role::Planning.name(), &args.common)?;
//! let pose = p.trigger(topics::LOCALIZATION_POSE, Order::Newest)?;
//! let scan = p.input(topics::SENSING_SCAN, Rule::SameTick)?;
//! let grid = p.input(topics::MAPPING_GRID, Rule::PreviousTick)?;
//! let mut cmd_out = p.output(topics::PLANNING_CMD)?;
//! p.run(|start| Planner::new(start.map), |planner, step| { ... cmd_out.publish(...) })
//! ```

use crate::clock::ClockMode;
use crate::context::{CommonArgs, Context};
use crate::error::{BadInput, RuntimeError};
use crate::params::Tuning;
use crate::ports::{Publisher, Subscriber, Waker};
use crate::waitset::Wake;
use mole_types::settings::Settings;
use mole_types::{Message, Role, Topic, WorldMap, topics};
use std::any::Any;
use std::marker::PhantomData;
use std::time::{Duration, Instant};

/// A replacement waits this long for each last output of the process it replaces, then starts
/// afresh.
pub const TAKEOVER_GRACE: Duration = Duration::from_secs(1);

/// Lockstep: a step held this long with its trigger but not its other inputs is reported.
const INCOMPLETE_WARNING: Duration = Duration::from_secs(2);
/// Lockstep: how long a step waits for a previous-tick input whose step k−1 was passed over
/// before it goes on without it (see `Gate::passed_over`).
const PASSED_OVER_GRACE: Duration = Duration::from_millis(300);

type BoxError = Box<dyn std::error::Error>;

/// Which of an input's samples a step uses, and whether a lockstep step waits for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rule {
    /// The sample of the step itself (tick k). Lockstep waits for it; realtime uses it only if
    /// it carries tick k (a missed reading is `None`, never last step's again).
    SameTick,
    /// The sample of the step before (tick k−1): lockstep waits for it and never hands out
    /// tick k even if it came early; step 0 has none. Realtime: the newest there is. For a
    /// producer that runs beside the loop (planning reads mapping's grid this way).
    PreviousTick,
    /// The newest sample there is, whatever its tick; never waited for.
    Newest,
}

/// How the trigger input (the one whose new tick starts a step) is read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Order {
    /// Its newest tick: a process in the loop, never behind it.
    Newest,
    /// Every tick, in order, in lockstep: a process beside the loop that may fall a step or two
    /// behind it and must still handle every step (mapping). Realtime: the newest.
    EveryTick,
}

/// A declared input of message type `M`; read it in a step with [`Step::get`].
pub struct In<M> {
    index: usize,
    _message: PhantomData<fn() -> M>,
}

/// The declared trigger input; read it in a step with [`Step::trigger`].
pub struct Trigger<M> {
    index: usize,
    _message: PhantomData<fn() -> M>,
}

impl<M> In<M> {
    /// The input declared at `index` of the process's ports.
    pub(crate) fn at(index: usize) -> In<M> {
        In {
            index,
            _message: PhantomData,
        }
    }
}

impl<M> Clone for In<M> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<M> Copy for In<M> {}
impl<M> Clone for Trigger<M> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<M> Copy for Trigger<M> {}

/// What `init` gets once the world's map is in.
pub struct Start<'a> {
    pub map: &'a WorldMap,
    /// The `--seed` override, or the scenario's.
    pub seed: u64,
    pub mode: ClockMode,
}

/// One step: its tick and its inputs, as their rules select them.
pub struct Step<'a> {
    tick: u64,
    origin_ns: u64,
    /// The tick this process handled last, or resumed after.
    previous: Option<u64>,
    ports: &'a [Box<dyn Port>],
}

impl Step<'_> {
    /// The step's tick k.
    pub fn tick(&self) -> u64 {
        self.tick
    }

    /// Ticks from the step this process handled last (or resumed after) to this one: 1 when
    /// none went by unhandled; more after a gap (a producer that crashed, this process
    /// restarted, a realtime step skipped under load); `None` on the first step of a fresh
    /// start.
    pub fn ticks_since_last(&self) -> Option<u64> {
        self.previous.map(|p| self.tick.saturating_sub(p))
    }

    /// The trigger's `origin_ns`: the stamp of the ground truth this step derives from, to pass
    /// on with every output (the loop latency is measured from it).
    pub fn origin_ns(&self) -> u64 {
        self.origin_ns
    }

    /// The trigger's sample of this step.
    pub fn trigger<M: Message>(&self, input: Trigger<M>) -> &M {
        self.port::<M>(input.index)
            .subscriber
            .latest()
            .expect("a step is due only once its trigger has a sample")
    }

    /// The input's sample for this step by its [`Rule`], if there is one.
    pub fn get<M: Message>(&self, input: In<M>) -> Option<&M> {
        let port = self.port::<M>(input.index);
        let latest = port.subscriber.latest()?;
        match port.rule {
            Rule::SameTick => (latest.header().tick == self.tick).then_some(latest),
            Rule::PreviousTick if port.lockstep => (self.tick > 0).then_some(latest),
            Rule::PreviousTick | Rule::Newest => Some(latest),
        }
    }

    fn port<M: Message>(&self, index: usize) -> &Input<M> {
        self.ports[index]
            .as_any()
            .downcast_ref::<Input<M>>()
            .expect("an input handle is used with the process that declared it")
    }
}

/// The tick an input with `rule` whose newest sample is at `newest` counts as in the lockstep
/// gate of step k (`None`: not there yet); a step is due when every input counts as k.
fn gate_tick(rule: Rule, newest: Option<u64>, k: u64) -> Option<u64> {
    match rule {
        Rule::SameTick => newest,
        // Step 0 has no previous step; step k needs k−1.
        Rule::PreviousTick if k == 0 => Some(0),
        Rule::PreviousTick => newest.map(|t| t + 1),
        Rule::Newest => Some(k),
    }
}

/// One input port, whatever its message type.
trait Port {
    /// Receives what the rule needs for the step the trigger (at `trigger_tick`) starts.
    fn refresh(&mut self, trigger_tick: u64);
    /// The tick this input counts as in the lockstep gate (`None`: not there yet).
    fn gate_tick(&self, trigger_tick: u64) -> Option<u64>;
    /// As the trigger: receives its next sample by `order`; `last` is the last step handled.
    fn refresh_trigger(&mut self, order: Order, last: Option<u64>);
    /// The newest sample's tick and `origin_ns`.
    fn tick(&self) -> Option<u64>;
    fn origin_ns(&self) -> u64;
    fn rule(&self) -> Rule;
    fn newest_seen(&self) -> Option<u64>;
    fn topic(&self) -> &'static str;
    fn as_any(&self) -> &dyn Any;
    fn as_any_mut(&mut self) -> &mut dyn Any;
    /// Drops every queued sample (nothing can use them yet).
    fn discard(&mut self);
    /// A look at the input's queue, for a WaitSet that wakes on another topic.
    fn pending(&self) -> std::rc::Rc<dyn crate::ports::Pending>;
}

struct Input<M: Message> {
    subscriber: Subscriber<M>,
    rule: Rule,
    lockstep: bool,
}

impl<M: Message> Port for Input<M> {
    fn refresh(&mut self, k: u64) {
        match (self.rule, self.lockstep) {
            (Rule::SameTick, true) => self.subscriber.update_through(k),
            (Rule::PreviousTick, true) if k == 0 => false,
            (Rule::PreviousTick, true) => self.subscriber.update_through(k - 1),
            _ => self.subscriber.update(),
        };
    }

    fn gate_tick(&self, k: u64) -> Option<u64> {
        gate_tick(self.rule, self.subscriber.tick(), k)
    }

    fn refresh_trigger(&mut self, order: Order, last: Option<u64>) {
        match (order, self.lockstep) {
            (Order::EveryTick, true) => self.subscriber.update_next(last),
            _ => self.subscriber.update(),
        };
    }
    fn tick(&self) -> Option<u64> {
        self.subscriber.tick()
    }
    fn origin_ns(&self) -> u64 {
        self.subscriber.latest().map_or(0, |m| m.header().origin_ns)
    }
    fn rule(&self) -> Rule {
        self.rule
    }
    fn newest_seen(&self) -> Option<u64> {
        self.subscriber.newest_seen()
    }
    fn topic(&self) -> &'static str {
        self.subscriber.topic()
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
    fn discard(&mut self) {
        self.subscriber.drain(|_| {});
    }
    fn pending(&self) -> std::rc::Rc<dyn crate::ports::Pending> {
        self.subscriber.pending()
    }
}

/// A role's main: its process in the stack the arguments name, handed to `dataflow` (the main's
/// own, which a unit test hands a [`crate::Harness`]'s process instead); the exit code says how
/// it ended ([`crate::exit_code`]).
pub fn run_role(
    role: Role,
    args: &CommonArgs,
    dataflow: impl FnOnce(Process) -> Result<(), BoxError>,
) -> std::process::ExitCode {
    crate::exit_code(
        Process::new(role.name(), args)
            .map_err(Into::into)
            .and_then(dataflow),
    )
}

/// A process of the control loop: its context, its declared inputs, its wake-ups.
pub struct Process {
    pub(crate) ctx: Context,
    /// The world's map. Subscribed before every other input: subscribed after them, a
    /// replacement joining a lockstep run (`mole swap sensing`) was not handed the map from
    /// history until its trigger's queue had stalled the world (3 s per step, measured).
    pub(crate) map: Subscriber<WorldMap>,
    ports: Vec<Box<dyn Port>>,
    /// The trigger: an index into `ports`, and how it is read.
    trigger: Option<(usize, Order)>,
    pub(crate) wakers: Vec<Waker>,
    /// Whether a waker for the loop's close is among `wakers` already (realtime, a process
    /// beside the loop: [`Process::wakes_after_the_loop`]).
    after_loop: bool,
    pub(crate) resume_after: Option<u64>,
    /// Lockstep, the clock: hold after step 0 until an operator paces the run.
    pub(crate) start_held: bool,
    /// The topics the main declared it reads and writes, checked against [`GRAPH`] at start.
    declared_inputs: Vec<&'static str>,
    declared_outputs: std::cell::RefCell<Vec<&'static str>>,
}

impl Process {
    /// The process `role` in the stack the arguments name (see [`Context::new`]).
    pub fn new(role: &str, args: &CommonArgs) -> Result<Process, RuntimeError> {
        Self::on(Context::new(role, args)?)
    }

    /// As [`Process::new`], for a caller that owns its signal handling (tests, tools).
    pub fn with_shutdown_flag(
        role: &str,
        args: &CommonArgs,
        shutdown: std::sync::Arc<std::sync::atomic::AtomicBool>,
    ) -> Result<Process, RuntimeError> {
        Self::on(Context::with_shutdown_flag(role, args, shutdown)?)
    }

    pub(crate) fn on(ctx: Context) -> Result<Process, RuntimeError> {
        Ok(Process {
            map: ctx.subscriber(topics::WORLD_MAP)?,
            ctx,
            ports: Vec::new(),
            trigger: None,
            wakers: Vec::new(),
            after_loop: false,
            resume_after: None,
            start_held: false,
            declared_inputs: vec![topics::WORLD_MAP.name],
            declared_outputs: Default::default(),
        })
    }

    /// Makes the clock ([`Process::run_clock`]) hold after step 0, in lockstep, until an
    /// operator paces the run (`mole up --paused`): so a test or a user can start several
    /// stacks and step them in turns from the same first step.
    pub fn start_held(&mut self) {
        self.start_held = true;
    }

    /// The process's context (mode, seed, namespace).
    pub fn context(&self) -> &Context {
        &self.ctx
    }

    /// The last sample of `topic`, one of this process's own outputs, published by the process
    /// this one follows, as a copy; the process then resumes after its tick. After a crash
    /// (`MOLE_RESUME`) it is the one the launcher kept; on a swap (`MOLE_TAKEOVER`) it waits up
    /// to [`TAKEOVER_GRACE`] for the predecessor, which still runs, to publish one. `None` when
    /// there is none (it starts afresh) or when this process follows none. Declare these before
    /// any input: a lockstep publisher waits while a queue is full, so an input not read while
    /// waiting here would stop the stack.
    pub fn resume_from<M: Message>(
        &mut self,
        topic: Topic<M>,
    ) -> Result<Option<Box<M>>, RuntimeError> {
        if !self.ports.is_empty() {
            return Err(RuntimeError::Setting(format!(
                "resume_from({}) comes after an input was declared: declare it first",
                topic.name
            )));
        }
        if let Some(dir) = self.ctx.resume_dir() {
            let kept = crate::keep::read_resume_file(dir, topic)?;
            match &kept {
                Some(message) => {
                    let tick = message.header().tick;
                    tracing::info!(
                        topic = topic.name,
                        tick,
                        "resumed from the last output kept"
                    );
                    self.resume_after = Some(tick);
                }
                None => tracing::warn!(
                    topic = topic.name,
                    "no last output was kept (none published before the crash): starting afresh"
                ),
            }
            return Ok(kept);
        }
        if !self.ctx.takes_over() {
            return Ok(None);
        }
        let mut copy = None;
        let tick = self.ctx.take_over(topic, TAKEOVER_GRACE, |message: &M| {
            let mut boxed: Box<M> = bytemuck::zeroed_box();
            *boxed = *message;
            copy = Some(boxed);
        })?;
        match tick {
            Some(tick) => {
                tracing::info!(topic = topic.name, tick, "took over the last output");
                self.resume_after = Some(tick);
            }
            None => tracing::warn!(
                topic = topic.name,
                "nothing to take over within {TAKEOVER_GRACE:?}: starting afresh"
            ),
        }
        Ok(copy)
    }

    /// Declares the input whose new tick starts a step. It wakes the process; in realtime, a
    /// process beside the loop ([`Order::EveryTick`]) is woken when the loop's step closes
    /// instead ([`Process::wakes_after_the_loop`]).
    pub fn trigger<M: Message>(
        &mut self,
        topic: Topic<M>,
        order: Order,
    ) -> Result<Trigger<M>, RuntimeError> {
        if self.trigger.is_some() {
            return Err(RuntimeError::Setting(format!(
                "{} is a second trigger: a process has one",
                topic.name
            )));
        }
        let index = match order {
            Order::EveryTick => self.add_beside_the_loop(topic, Rule::SameTick)?,
            Order::Newest => self.add(topic, Rule::SameTick, true)?,
        };
        self.trigger = Some((index, order));
        Ok(Trigger {
            index,
            _message: PhantomData,
        })
    }

    /// Declares an input read by `rule`. A [`Rule::PreviousTick`] input wakes the process (it
    /// may come after the trigger); the others are read when the trigger wakes it, so they
    /// must be published before the trigger (sensing publishes odometry last).
    pub fn input<M: Message>(
        &mut self,
        topic: Topic<M>,
        rule: Rule,
    ) -> Result<In<M>, RuntimeError> {
        let wakes = rule == Rule::PreviousTick && self.ctx.mode() == ClockMode::Lockstep;
        self.add_input(topic, rule, wakes)
    }

    pub(crate) fn add_input<M: Message>(
        &mut self,
        topic: Topic<M>,
        rule: Rule,
        wakes: bool,
    ) -> Result<In<M>, RuntimeError> {
        Ok(In::at(self.add(topic, rule, wakes)?))
    }

    /// Declares an input of a process beside the loop that wakes it: in lockstep when the input is
    /// published, in realtime when the loop's step closes ([`Process::wakes_after_the_loop`]).
    pub(crate) fn add_beside_the_loop<M: Message>(
        &mut self,
        topic: Topic<M>,
        rule: Rule,
    ) -> Result<usize, RuntimeError> {
        if self.ctx.mode() == ClockMode::Lockstep {
            return self.add(topic, rule, true);
        }
        let index = self.add(topic, rule, false)?;
        if !self.after_loop {
            let pending = self.ports[index].pending();
            self.wakers.push(self.ctx.loop_closed_waker(pending)?);
            self.after_loop = true;
        }
        Ok(index)
    }

    /// Whether this process is woken when the loop's step closes (the command that ends it is
    /// published) rather than by its own inputs: realtime, beside the loop (mapping, the
    /// monitor, an observer). It then runs while the loop's processes sleep until the next step,
    /// instead of taking a CPU from them while they pass the step on. Its inputs were all
    /// published before the command; with no command (no planner), it looks at them when its
    /// WaitSet times out.
    pub fn wakes_after_the_loop(&self) -> bool {
        self.after_loop
    }

    /// An input's subscriber, for a loop that reads it itself (an observer).
    pub(crate) fn input_mut<M: Message>(&mut self, input: In<M>) -> &mut Subscriber<M> {
        &mut self.ports[input.index]
            .as_any_mut()
            .downcast_mut::<Input<M>>()
            .expect("an input handle is used with the process that declared it")
            .subscriber
    }

    /// A publisher for one of the process's outputs.
    pub fn output<M: Message>(&self, topic: Topic<M>) -> Result<Publisher<M>, RuntimeError> {
        self.declared_outputs.borrow_mut().push(topic.name);
        self.ctx.publisher(topic)
    }

    /// A role's ports are the graph's: the topics its main declared it reads (`extra`: those
    /// its loop opens itself) and writes must be its row of [`GRAPH`], or it fails at start,
    /// naming the difference. A process in no role of the graph (an observer, a tool) passes.
    pub(crate) fn check_ports_against_the_graph(
        &self,
        extra: &[&'static str],
    ) -> Result<(), RuntimeError> {
        let Ok(role) = self.ctx.role().parse::<Role>() else {
            return Ok(());
        };
        let spec = role.spec();
        let sorted = |topics: &[&'static str]| {
            let mut v = topics.to_vec();
            v.sort_unstable();
            v.dedup();
            v
        };
        let mut inputs = sorted(&[&self.declared_inputs[..], extra].concat());
        // Every process follows the map; the one that writes it does not read it.
        inputs.retain(|t| !spec.outputs.contains(t));
        let outputs = sorted(&self.declared_outputs.borrow());
        for (what, declared, graph) in [
            ("reads", inputs, sorted(spec.inputs)),
            ("writes", outputs, sorted(spec.outputs)),
        ] {
            if declared != graph {
                return Err(RuntimeError::Setting(format!(
                    "the {role} process {what} {declared:?}, but its row of the graph \
                     (mole_types::GRAPH) says {graph:?}: declare the graph's ports, or change \
                     the graph"
                )));
            }
        }
        Ok(())
    }

    /// Until the map is in nothing can use the inputs; left unread, their queues would fill
    /// and, in lockstep, stall their publishers, and with them the world that sends the map to
    /// a process joining a run.
    pub(crate) fn discard_inputs(&mut self) {
        for port in &mut self.ports {
            port.discard();
        }
    }

    /// The trigger's subscriber, for a loop that reads it itself (the clock).
    pub(crate) fn subscriber_mut<M: Message>(&mut self, input: Trigger<M>) -> &mut Subscriber<M> {
        &mut self.ports[input.index]
            .as_any_mut()
            .downcast_mut::<Input<M>>()
            .expect("an input handle is used with the process that declared it")
            .subscriber
    }

    fn add<M: Message>(
        &mut self,
        topic: Topic<M>,
        rule: Rule,
        wakes: bool,
    ) -> Result<usize, RuntimeError> {
        self.declared_inputs.push(topic.name);
        let subscriber = if wakes {
            self.ctx.subscriber(topic)?
        } else {
            self.ctx.passive_subscriber(topic)?
        };
        if wakes {
            self.wakers.push(subscriber.waker());
        }
        self.ports.push(Box::new(Input {
            subscriber,
            rule,
            lockstep: self.ctx.mode() == ClockMode::Lockstep,
        }));
        Ok(self.ports.len() - 1)
    }

    /// Runs until shutdown: `init` once the world's map is in, then `step` once per due step,
    /// every step in order. An error from either ends the process with it.
    pub fn run<S>(
        self,
        init: impl FnOnce(&Start) -> Result<S, BoxError>,
        step: impl FnMut(&mut S, &Step) -> Result<(), BoxError>,
    ) -> Result<(), BoxError> {
        self.run_with(init, step, |_, _| Ok(()))
    }

    /// This role's settings (`MOLE_SETTINGS`, docs/settings.md), checked, with the ports that
    /// change them while it runs: hand them to [`Process::run_tuned`].
    pub fn tuning<T: Settings>(&self, args: &CommonArgs) -> Result<Tuning<T>, BadInput> {
        let role: Role = self
            .ctx
            .role()
            .parse()
            .map_err(|e| BadInput(format!("settings: {e}")))?;
        Tuning::new(&self.ctx, args, role)
    }

    /// [`Process::run`] for a process whose settings change while it runs (`mole param set`):
    /// before each step, every change due is checked against the settings and handed to `tune`
    /// with the new settings; what `tune` refuses (with the reason) changes nothing.
    pub fn run_tuned<S, T: Settings>(
        self,
        mut tuning: Tuning<T>,
        init: impl FnOnce(&Start) -> Result<S, BoxError>,
        step: impl FnMut(&mut S, &Step) -> Result<(), BoxError>,
        mut tune: impl FnMut(&mut S, &T) -> Result<(), String>,
    ) -> Result<(), BoxError> {
        self.run_with(init, step, move |k, state| {
            Ok(tuning.before_step(k, state, &mut tune)?)
        })
    }

    fn run_with<S>(
        mut self,
        init: impl FnOnce(&Start) -> Result<S, BoxError>,
        mut step: impl FnMut(&mut S, &Step) -> Result<(), BoxError>,
        mut before_step: impl FnMut(u64, &mut S) -> Result<(), BoxError>,
    ) -> Result<(), BoxError> {
        let Some((trigger, order)) = self.trigger else {
            return Err(RuntimeError::Setting("a process needs a trigger input".into()).into());
        };
        self.check_ports_against_the_graph(&[])?;
        let waitset = self.ctx.waitset()?;
        let mut wakers = std::mem::take(&mut self.wakers);
        wakers.push(self.map.waker());
        let _attached = waitset.attach_all(&wakers)?;
        self.ctx.ready();
        let mut gate = Gate::new(self.ctx.mode(), self.resume_after);
        let mut init = Some(init);
        let mut state = None;
        let mut handled = self.resume_after;
        loop {
            if waitset.wait(&mut self.ctx, None)? == Wake::Shutdown {
                return Ok(());
            }
            follow_map(&self.ctx, &mut self.map, &mut init, &mut state)?;
            let Some(state) = state.as_mut() else {
                // Before the map, realtime readings are stale; lockstep ones are steps owed to
                // this process (a restart's, handed from history before the world's map came),
                // so they stay queued: discarded, the restart skipped a step (the grid differed).
                if self.ctx.mode() == ClockMode::Realtime {
                    self.discard_inputs();
                }
                continue;
            };
            // Every due step, in order: a process beside the loop may have fallen behind.
            loop {
                self.ports[trigger].refresh_trigger(order, gate.last);
                let Some(k) = self.ports[trigger].tick() else {
                    break;
                };
                for (i, port) in self.ports.iter_mut().enumerate() {
                    if i != trigger {
                        port.refresh(k);
                    }
                }
                match gate.due(k, trigger, &self.ports) {
                    Due::Step => {}
                    Due::Skip => continue,
                    Due::NotYet => break,
                }
                if self.ctx.mode() == ClockMode::Lockstep
                    && order == Order::EveryTick
                    && let Some(h) = handled
                    && k > h + 1
                {
                    // Every step of a process beside the loop is owed to it: a gap changes
                    // its output (a map built without a scan) and must not pass silently.
                    tracing::warn!(
                        tick = k,
                        after = h,
                        "lockstep: steps {} to {} were never handed to this process",
                        h + 1,
                        k - 1
                    );
                }
                before_step(k, state)?;
                let origin_ns = self.ports[trigger].origin_ns();
                let this_step = Step {
                    tick: k,
                    origin_ns,
                    previous: handled,
                    ports: &self.ports,
                };
                self.ctx.timed_step(|| step(state, &this_step))?;
                handled = Some(k);
                self.ctx.count_step();
            }
        }
    }
}

/// Inputs from and outputs to other robots' stacks (other namespaces on the same machine).
impl Process {
    /// Declares an input read from another robot: `topic` as the robot in namespace `peer`
    /// offers it ([`Process::peer_output`]). Read by [`Rule::Newest`]: it never wakes this
    /// process and never gates a step (the peer runs its own clock), and each step drains its
    /// queue; a queue that fills anyway (this robot not stepping) drops its oldest sample, so it
    /// never holds the peer back either. Nothing is read until the peer's stack publishes.
    pub fn peer_input<M: Message>(
        &mut self,
        peer: &str,
        topic: Topic<M>,
    ) -> Result<In<M>, RuntimeError> {
        let subscriber = self.ctx.peer_subscriber(peer, topic)?;
        self.ports.push(Box::new(Input {
            subscriber,
            rule: Rule::Newest,
            lockstep: self.ctx.mode() == ClockMode::Lockstep,
        }));
        Ok(In {
            index: self.ports.len() - 1,
            _message: PhantomData,
        })
    }

    /// A publisher offering `topic` to other robots (see [`Context::peer_publisher`]): it never
    /// waits for a reader, in lockstep either.
    pub fn peer_output<M: Message>(&self, topic: Topic<M>) -> Result<Publisher<M>, RuntimeError> {
        self.ctx.peer_publisher(topic)
    }
}

/// Runs `init` once the world's map is in (every process but the clock starts from it), into
/// `state`. After that it takes each map the world publishes again (a restarted world sends its
/// map once more): left in the queue, that sample would end every wait at once, and in lockstep
/// keep the wait from offering history to a process restarted later, which then never got the
/// step it waited for (a chaos session stalled so: the world restarted, later mapping and
/// planning).
pub(crate) fn follow_map<S>(
    ctx: &Context,
    map: &mut Subscriber<WorldMap>,
    init: &mut Option<impl FnOnce(&Start) -> Result<S, BoxError>>,
    state: &mut Option<S>,
) -> Result<(), BoxError> {
    if state.is_some() {
        if map.drain(|_| {}) > 0 {
            tracing::info!(
                role = ctx.role(),
                "the world published its map again (it restarted): going on with the one we have"
            );
        }
        return Ok(());
    }
    if !map.update() {
        return Ok(());
    }
    let (Some(world), Some(init)) = (map.latest(), init.take()) else {
        return Ok(());
    };
    let start = Start {
        map: world,
        seed: ctx.seed().unwrap_or(world.seed),
        mode: ctx.mode(),
    };
    *state = Some(init(&start)?);
    tracing::info!(role = ctx.role(), "map received");
    Ok(())
}

/// What the gate decided for the trigger's tick.
enum Due {
    Step,
    /// A step that cannot complete (its readings were sent before this process listened):
    /// marked handled, go on with the next.
    Skip,
    NotYet,
}

/// Decides whether the trigger's tick k is a step to handle now (docs/architecture.md, "Clock
/// modes"): realtime, whenever k is new; lockstep, when k is new and every waited-for input is
/// in for k.
struct Gate {
    mode: ClockMode,
    last: Option<u64>,
    skipped: u64,
    incomplete: Option<(u64, Instant)>,
    warned: bool,
    passed_over_grace: Duration,
}

impl Gate {
    fn new(mode: ClockMode, resume_after: Option<u64>) -> Gate {
        Gate {
            mode,
            last: resume_after,
            skipped: 0,
            incomplete: None,
            warned: false,
            passed_over_grace: PASSED_OVER_GRACE,
        }
    }

    /// When step k was first found incomplete.
    fn held_since(&mut self, k: u64) -> Instant {
        match self.incomplete {
            Some((held, since)) if held == k => since,
            _ => self.incomplete.insert((k, Instant::now())).1,
        }
    }

    /// Whether step k, complete but for previous-tick inputs whose step k−1 was passed over
    /// (a later sample is in), has waited [`PASSED_OVER_GRACE`] for them: a process that joined
    /// a run is handed only its inputs' newest sample, and a producer restarted after a crash
    /// goes on past the step it lost, so that step k−1 will not come and the step goes on with
    /// the input's older sample. The grace keeps a swap, whose two producers may deliver k
    /// before k−1, deterministic.
    fn passed_over(&mut self, k: u64, trigger: usize, ports: &[Box<dyn Port>]) -> bool {
        let mut any = false;
        for (i, p) in ports.iter().enumerate() {
            if i == trigger || p.gate_tick(k) == Some(k) {
                continue;
            }
            if p.rule() != Rule::PreviousTick || p.newest_seen().is_none_or(|t| t < k) {
                return false;
            }
            any = true;
        }
        if !any || self.held_since(k).elapsed() < self.passed_over_grace {
            return false;
        }
        tracing::warn!(
            tick = k,
            "lockstep: step {k} goes on without a previous step's input that was passed over"
        );
        true
    }

    fn due(&mut self, k: u64, trigger: usize, ports: &[Box<dyn Port>]) -> Due {
        if self.last.is_some_and(|last| k <= last) {
            return Due::NotYet;
        }
        if self.mode == ClockMode::Realtime {
            self.last = Some(k);
            return Due::Step;
        }
        let complete = ports
            .iter()
            .enumerate()
            .all(|(i, p)| i == trigger || p.gate_tick(k) == Some(k));
        if complete || self.passed_over(k, trigger, ports) {
            if self.skipped > 0 {
                tracing::info!(
                    skipped = self.skipped,
                    tick = k,
                    "joined the run: skipped the steps whose readings came before us"
                );
                self.skipped = 0;
            }
            self.incomplete = None;
            self.last = Some(k);
            return Due::Step;
        }
        // Joined mid-run (a swap or a restart): a step whose readings were sent before we
        // listened never completes; once a later reading is in, go on without it.
        let later = ports.iter().enumerate().any(|(i, p)| {
            i != trigger && p.rule() == Rule::SameTick && p.newest_seen().is_some_and(|t| t > k)
        });
        if later {
            self.skipped += 1;
            self.last = Some(k);
            return Due::Skip;
        }
        // Held this long without its inputs: a step that cannot complete; say what is missing.
        let since = self.held_since(k);
        if since.elapsed() > INCOMPLETE_WARNING && !self.warned {
            self.warned = true;
            let missing: Vec<&str> = ports
                .iter()
                .enumerate()
                .filter(|(i, p)| *i != trigger && p.gate_tick(k) != Some(k))
                .map(|(_, p)| p.topic())
                .collect();
            tracing::warn!(
                ?missing,
                "lockstep: step {k} has its trigger but not all its inputs"
            );
        }
        Due::NotYet
    }
}

/// The step rules' decisions as JSON, for the processes written in other languages to be
/// tested against (examples/python_planner/step_rules.json): [`gate_tick`] for every rule,
/// newest tick (none, 0 to 4) and step k (0 to 4), and the gate's verdict for a trigger at k
/// (0 to 4) with a `SameTick` input (none, k−1 or k; a later reading seen or not), a
/// `PreviousTick` input (none, k−2 to k) and a `Newest` one (none), in both clock modes, after
/// no step or after step 2.
pub fn rule_table() -> String {
    const RULES: [Rule; 3] = [Rule::SameTick, Rule::PreviousTick, Rule::Newest];
    let ticks = || std::iter::once(None).chain((0..5).map(Some));
    let mut lines = Vec::new();
    for rule in RULES {
        for newest in ticks() {
            for k in 0..5 {
                lines.push(format!(
                    "    {{\"rule\": \"{}\", \"newest\": {}, \"k\": {k}, \"counts_as\": {}}}",
                    rule_name(rule),
                    json_tick(newest),
                    json_tick(gate_tick(rule, newest, k)),
                ));
            }
        }
    }
    let gate_ticks = lines.join(",\n");
    let mut lines = Vec::new();
    for (mode, mode_name) in [
        (ClockMode::Realtime, "realtime"),
        (ClockMode::Lockstep, "lockstep"),
    ] {
        for last in [None, Some(2)] {
            for k in 0..5_u64 {
                let around = |back: u64| (0..=back).rev().filter_map(move |d| k.checked_sub(d));
                for same in std::iter::once(None).chain(around(1).map(Some)) {
                    for seen in [None, Some(k + 1)] {
                        for previous in std::iter::once(None).chain(around(2).map(Some)) {
                            let inputs = [
                                (Rule::SameTick, same, seen),
                                (Rule::PreviousTick, previous, None),
                                (Rule::Newest, None, None),
                            ];
                            lines.push(gate_case(mode, mode_name, last, k, &inputs));
                        }
                    }
                }
            }
        }
    }
    format!(
        "{{\n  \"gate_tick\": [\n{gate_ticks}\n  ],\n  \"gate\": [\n{}\n  ]\n}}\n",
        lines.join(",\n")
    )
}

/// One gate case of [`rule_table`]: the trigger at k and `inputs` (rule, newest tick, newest
/// tick seen), after step `last`, as a JSON object with the verdict.
fn gate_case(
    mode: ClockMode,
    mode_name: &str,
    last: Option<u64>,
    k: u64,
    inputs: &[(Rule, Option<u64>, Option<u64>)],
) -> String {
    let mut ports: Vec<Box<dyn Port>> = vec![Box::new(TableInput {
        rule: Rule::SameTick,
        tick: Some(k),
        seen: None,
    })];
    ports.extend(
        inputs
            .iter()
            .map(|&(rule, tick, seen)| Box::new(TableInput { rule, tick, seen }) as Box<dyn Port>),
    );
    let due = match Gate::new(mode, last).due(k, 0, &ports) {
        Due::Step => "step",
        Due::Skip => "skip",
        Due::NotYet => "not yet",
    };
    let inputs: Vec<String> = inputs
        .iter()
        .map(|&(rule, tick, seen)| {
            format!(
                "{{\"rule\": \"{}\", \"newest\": {}, \"seen\": {}}}",
                rule_name(rule),
                json_tick(tick),
                json_tick(seen)
            )
        })
        .collect();
    format!(
        "    {{\"mode\": \"{mode_name}\", \"last\": {}, \"k\": {k}, \"inputs\": [{}], \"due\": \"{due}\"}}",
        json_tick(last),
        inputs.join(", ")
    )
}

/// A rule's name in [`rule_table`].
fn rule_name(rule: Rule) -> &'static str {
    match rule {
        Rule::SameTick => "same_tick",
        Rule::PreviousTick => "previous_tick",
        Rule::Newest => "newest",
    }
}

/// A tick in [`rule_table`]: a number, or `null` for none.
fn json_tick(tick: Option<u64>) -> String {
    tick.map_or_else(|| "null".to_string(), |t| t.to_string())
}

/// An input of a [`rule_table`] case: its rule, its newest tick and the newest tick seen (a
/// held-back one's), without a queue.
struct TableInput {
    rule: Rule,
    tick: Option<u64>,
    seen: Option<u64>,
}

impl Port for TableInput {
    fn refresh(&mut self, _: u64) {}
    fn gate_tick(&self, k: u64) -> Option<u64> {
        gate_tick(self.rule, self.tick, k)
    }
    fn refresh_trigger(&mut self, _: Order, _: Option<u64>) {}
    fn tick(&self) -> Option<u64> {
        self.tick
    }
    fn origin_ns(&self) -> u64 {
        0
    }
    fn rule(&self) -> Rule {
        self.rule
    }
    fn newest_seen(&self) -> Option<u64> {
        self.seen.max(self.tick)
    }
    fn topic(&self) -> &'static str {
        "table/input"
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
    fn discard(&mut self) {}
    fn pending(&self) -> std::rc::Rc<dyn crate::ports::Pending> {
        unreachable!("a rule table input has no queue")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ports(inputs: &[(Rule, Option<u64>)]) -> Vec<Box<dyn Port>> {
        inputs
            .iter()
            .map(|&(rule, tick)| {
                Box::new(TableInput {
                    rule,
                    tick,
                    seen: None,
                }) as Box<dyn Port>
            })
            .collect()
    }

    fn set(ports: &mut [Box<dyn Port>], i: usize, tick: u64) {
        let p = ports[i].as_any_mut().downcast_mut::<TableInput>().unwrap();
        p.tick = Some(tick);
    }

    fn due(gate: &mut Gate, k: u64, ports: &[Box<dyn Port>]) -> &'static str {
        match gate.due(k, 0, ports) {
            Due::Step => "step",
            Due::Skip => "skip",
            Due::NotYet => "not yet",
        }
    }

    #[test]
    fn lockstep_waits_for_every_same_tick_input_and_handles_a_tick_once() {
        let mut gate = Gate::new(ClockMode::Lockstep, None);
        let mut p = ports(&[(Rule::SameTick, Some(0)), (Rule::SameTick, None)]);
        assert_eq!(due(&mut gate, 0, &p), "not yet");
        set(&mut p, 1, 0);
        assert_eq!(due(&mut gate, 0, &p), "step");
        assert_eq!(due(&mut gate, 0, &p), "not yet", "handled once");
        set(&mut p, 0, 1);
        assert_eq!(due(&mut gate, 1, &p), "not yet", "input still at 0");
    }

    #[test]
    fn lockstep_previous_tick_needs_k_minus_1_except_at_step_0() {
        let mut gate = Gate::new(ClockMode::Lockstep, None);
        let mut p = ports(&[(Rule::SameTick, Some(0)), (Rule::PreviousTick, None)]);
        assert_eq!(due(&mut gate, 0, &p), "step", "step 0 has no previous step");
        set(&mut p, 0, 1);
        assert_eq!(due(&mut gate, 1, &p), "not yet", "needs the grid of step 0");
        set(&mut p, 1, 0);
        assert_eq!(due(&mut gate, 1, &p), "step");
        set(&mut p, 0, 2);
        set(&mut p, 1, 2);
        assert_eq!(
            due(&mut gate, 2, &p),
            "not yet",
            "tick k of a previous-tick input is not k−1"
        );
    }

    /// A previous-tick input whose step k−1 was passed over (only k came: a process that
    /// joined gets the newest sample) holds step k for the grace, then lets it go on.
    #[test]
    fn lockstep_previous_tick_passed_over_goes_on_after_the_grace() {
        let mut gate = Gate::new(ClockMode::Lockstep, None);
        let mut p = ports(&[(Rule::SameTick, Some(5)), (Rule::PreviousTick, None)]);
        let grid = p[1].as_any_mut().downcast_mut::<TableInput>().unwrap();
        grid.seen = Some(5);
        assert_eq!(due(&mut gate, 5, &p), "not yet", "within the grace");
        gate.passed_over_grace = Duration::ZERO;
        assert_eq!(due(&mut gate, 5, &p), "step");
        // Not passed over (nothing later seen): still waited for.
        let mut gate = Gate::new(ClockMode::Lockstep, None);
        gate.passed_over_grace = Duration::ZERO;
        let p = ports(&[(Rule::SameTick, Some(5)), (Rule::PreviousTick, Some(3))]);
        assert_eq!(due(&mut gate, 5, &p), "not yet");
    }

    #[test]
    fn newest_inputs_are_never_waited_for() {
        let mut gate = Gate::new(ClockMode::Lockstep, None);
        let p = ports(&[(Rule::SameTick, Some(4)), (Rule::Newest, None)]);
        assert_eq!(due(&mut gate, 4, &p), "step");
    }

    #[test]
    fn realtime_steps_on_every_new_trigger_tick_whatever_the_other_inputs() {
        let mut gate = Gate::new(ClockMode::Realtime, None);
        let p = ports(&[(Rule::SameTick, Some(5)), (Rule::SameTick, None)]);
        assert_eq!(due(&mut gate, 5, &p), "step");
        assert_eq!(due(&mut gate, 5, &p), "not yet");
        assert_eq!(
            due(&mut gate, 3, &p),
            "not yet",
            "an older tick is never a step"
        );
        assert_eq!(due(&mut gate, 7, &p), "step");
    }

    #[test]
    fn a_replacement_resumes_after_the_tick_it_took_over() {
        let mut gate = Gate::new(ClockMode::Lockstep, Some(9));
        let p = ports(&[(Rule::SameTick, Some(9)), (Rule::SameTick, Some(9))]);
        assert_eq!(
            due(&mut gate, 9, &p),
            "not yet",
            "step 9 was the predecessor's"
        );
        let p = ports(&[(Rule::SameTick, Some(10)), (Rule::SameTick, Some(10))]);
        assert_eq!(due(&mut gate, 10, &p), "step");
    }

    #[test]
    fn joining_mid_run_skips_a_step_whose_readings_came_before_it_listened() {
        let mut gate = Gate::new(ClockMode::Lockstep, None);
        let mut p = ports(&[(Rule::SameTick, Some(3)), (Rule::SameTick, None)]);
        assert_eq!(
            due(&mut gate, 3, &p),
            "not yet",
            "the reading of 3 may still come"
        );
        p[1].as_any_mut().downcast_mut::<TableInput>().unwrap().seen = Some(4);
        assert_eq!(
            due(&mut gate, 3, &p),
            "skip",
            "a reading of 4 is in: 3's never comes"
        );
        assert_eq!(gate.last, Some(3));
        set(&mut p, 0, 4);
        set(&mut p, 1, 4);
        assert_eq!(due(&mut gate, 4, &p), "step");
    }

    /// examples/python_planner/step_rules.json, which the Python runtime is tested against, is
    /// what these rules decide (`MOLE_BLESS=1` rewrites it).
    #[test]
    fn python_planner_step_rules_json_matches_the_rules() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../examples/python_planner/step_rules.json"
        );
        mole_types::golden::check(
            path.as_ref(),
            &rule_table(),
            mole_types::golden::whole,
            "cargo test -p mole-runtime --lib step",
        );
    }
}
