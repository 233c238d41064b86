//! `mole up` in four stages: [`prepare`] (launch file, scenario, overrides, environment: every
//! refusal happens here, before anything starts), [`start`] (the processes in dependency
//! order), [`supervise`] (until the run ends: a typed [`RunEnd`]) and [`finish`] (stop in the
//! graph's order, complete summary.json).

mod control;
mod finish;
mod prepare;
mod start;
mod supervise;

use crate::Failure;
use crate::hot_swap::{SwapEnv, SwapError, SwapReport, check_swappable, hot_swap};
use crate::inject::Injector;
use crate::keeper::ResumeKeeper;
use crate::param::Tuner;
use crate::record::{RecordPlan, Recorder};
use crate::servers::{ServerPlan, SideServer, UpFoxgloveArgs, UpViewArgs};
use crate::stats::StatsCollector;
use crate::supervisor::EXIT_BAD_INPUT;
use crate::supervisor::last_error_line;
use crate::{
    ChildSpec, ExitStatus, LaunchFile, RestartWhen, Supervisor, SupervisorEvent, resolve_program,
    start_order, stop_order,
};
use clap::Args;
use control::*;
use finish::*;
use indicatif::{ProgressBar, ProgressStyle};
use mole_monitor::{Summary, SwapRecord, read_summary, write_summary};
use mole_runtime::{CommonArgs, Context, ControlServer, Publisher, Subscriber, cleanup_dead_nodes};
use mole_types::graph::nodes;
use mole_types::{
    CONTROL_FAILED, CONTROL_FAULT, CONTROL_OK, CONTROL_PARAM, CONTROL_REFUSED, CONTROL_STATUS,
    CONTROL_STOP, ClockMode, ControlRequest, EndReason, EstimatorKind, FaultSpec, PlannerKind,
    Processes, Role, RunStatus, Stats, read_name, topics, write_name,
};
use prepare::{Plan, prepare};
use start::*;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use supervise::*;

/// How long a process may take to announce that its ports exist.
const READY_TIMEOUT: Duration = Duration::from_secs(20);
/// How long the monitor may take to write its files once the world has finished.
const FINISH_TIMEOUT: Duration = Duration::from_secs(30);
/// A ready process that publishes no statistics for this long is hung: alive but not serving.
const HANG_TIMEOUT: Duration = Duration::from_secs(5);
/// Lockstep: no new step for this long, every process alive, is a stall the run cannot leave by
/// itself (the world resends a step every second, a hung process is restarted after
/// `HANG_TIMEOUT`); the run ends instead of waiting forever.
const STALL_TIMEOUT: Duration = Duration::from_secs(15);
/// The launcher's wake-up period (supervision and progress).
const POLL: Duration = Duration::from_millis(50);
/// Where, in the run's directory, the keeper writes a crashed role's last outputs for its
/// restart (removed at the end of the run).
const RESUME_DIR: &str = "resume";

/// A command-line value that is one of `names`, listed in `--help` and in the error for any
/// other (the names come from the kind's one declaration, `mole_types::kinds`).
pub(crate) fn choices<T: Clone + Send + Sync + 'static, E: std::fmt::Debug + 'static>(
    names: &'static [&'static str],
    parse: fn(&str) -> Result<T, E>,
) -> impl clap::builder::TypedValueParser<Value = T> {
    use clap::builder::TypedValueParser;
    clap::builder::PossibleValuesParser::new(names)
        .map(move |name| parse(&name).expect("a name from the kind's own list parses"))
}

#[derive(Debug, Clone, Args)]
pub struct UpArgs {
    /// Launch file (default: launch/stacks/default.toml).
    pub launch: Option<PathBuf>,
    /// Scenario file, instead of the launch file's.
    #[arg(long)]
    pub scenario: Option<PathBuf>,
    /// Planner, instead of the launch file's.
    #[arg(long, value_parser = choices(PlannerKind::NAMES, str::parse::<PlannerKind>))]
    pub planner: Option<PlannerKind>,
    /// Estimator, instead of the launch file's.
    #[arg(long, value_parser = choices(EstimatorKind::NAMES, str::parse::<EstimatorKind>))]
    pub estimator: Option<EstimatorKind>,
    /// Clock mode.
    #[arg(long, value_parser = choices(ClockMode::NAMES, str::parse::<ClockMode>))]
    pub mode: Option<ClockMode>,
    /// Steps to run.
    #[arg(long, conflicts_with = "duration")]
    pub ticks: Option<u64>,
    /// Simulated seconds to run.
    #[arg(long)]
    pub duration: Option<f64>,
    /// Lockstep: hold after step 0 until an operator (the view, a script) paces the run.
    #[arg(long)]
    pub paused: bool,
    /// Goal X,Y (m) for the goal-seeking planners (apf, dwa), instead of the scenario's.
    #[arg(long, value_name = "X,Y", value_parser = mole_runtime::parse_point)]
    pub goal: Option<(f64, f64)>,
    /// Local planner that follows frontier paths: dwa or apf.
    #[arg(long, value_name = "dwa|apf")]
    pub local_planner: Option<PlannerKind>,
    /// Seed for every random number of the run.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Namespace: services are mole/<namespace>/<topic>.
    #[arg(long, default_value = mole_types::env::DEFAULT_NAMESPACE)]
    pub namespace: String,
    /// Output directory for summary.json, map.png and the process logs.
    #[arg(long, default_value = "runs/latest")]
    pub out: PathBuf,
    /// Run another executable in a role's place: ROLE=COMMAND (repeatable).
    #[arg(long = "swap", value_name = "ROLE=COMMAND")]
    pub swaps: Vec<String>,
    /// Set a setting for this run, over the launch file's: ROLE.KEY=VALUE, e.g.
    /// planning.dwa.critics.heading=0.4 (repeatable; docs/settings.md lists the keys).
    #[arg(long = "set", value_name = "ROLE.KEY=VALUE")]
    pub sets: Vec<String>,
    /// Settings that replace the launch file's before `--set` (`mole replay`: the recording's).
    #[arg(skip)]
    pub settings: Option<Box<crate::settings::StackSettings>>,
    /// Settings changes each process applies before a step (`mole replay`: the recording's).
    #[arg(skip)]
    pub settings_changes: Vec<mole_runtime::ScheduledChange>,
    /// No progress bar (logs only).
    #[arg(long)]
    pub quiet: bool,
    /// Record every topic of the run into this MCAP file (`mole info FILE` describes it).
    #[arg(long, value_name = "FILE")]
    pub record: Option<PathBuf>,
    /// With --record: write TOPIC's samples every N ticks only (repeatable; default
    /// mapping/grid=10 and mapping/contact=10; N = 1 writes every sample).
    #[arg(long = "record-every", value_name = "TOPIC=N", requires = "record")]
    pub record_every: Vec<String>,
    #[command(flatten)]
    pub view: UpViewArgs,
    #[command(flatten)]
    pub foxglove: UpFoxgloveArgs,
    /// `mole replay`: the player in the place of the roles it plays back.
    #[arg(skip)]
    pub stand_in: Option<Box<crate::stand_in::StandIn>>,
}

/// How a run ended, as the launcher saw it.
#[derive(Debug)]
pub enum RunEnd {
    /// The world ended the run (its end reason stands) and the monitor wrote its files.
    Finished,
    /// `mole stop` asked for it.
    Stopped,
    /// Ctrl-C.
    Interrupted,
    /// The lockstep run made no step for [`STALL_TIMEOUT`].
    Stalled(Failure),
    /// A process failed beyond what its restart policy mends.
    ProcessFailed(Failure),
}

impl RunEnd {
    /// summary.json's `exit_reason` for this end; `None` keeps the monitor's (the world's).
    pub fn exit_reason(&self) -> Option<&'static str> {
        match self {
            RunEnd::Finished => None,
            RunEnd::Stopped => Some(EndReason::Stopped.name()),
            RunEnd::Interrupted => Some("interrupted"),
            RunEnd::Stalled(_) => Some("stalled"),
            RunEnd::ProcessFailed(_) => Some("process_failed"),
        }
    }

    /// The failure `mole up` exits with, if the run failed.
    fn into_failure(self) -> Option<Failure> {
        match self {
            RunEnd::Stalled(f) | RunEnd::ProcessFailed(f) => Some(f),
            RunEnd::Finished | RunEnd::Stopped | RunEnd::Interrupted => None,
        }
    }
}

/// What a run leaves besides its files.
pub struct RunOutcome {
    /// summary.json of the run.
    pub summary_path: PathBuf,
    /// The summary as the launcher completed it; `None` for a half of a split stack without the
    /// monitor (the other half writes it).
    pub summary: Option<Summary>,
    /// What the processes reported on stack/stats.
    pub stats: StatsCollector,
}

/// Runs the stack to its end (or Ctrl-C); the summary is in `args.out`.
pub fn up(args: &UpArgs) -> Result<RunOutcome, Failure> {
    let mut plan = prepare(args)?;
    if let Some(stand_in) = &args.stand_in {
        stand_in.apply(&mut plan.launch, &mut plan.programs, &plan.beside)?;
    }
    let recording = match &args.record {
        Some(file) => Some(RecordPlan::new(
            file,
            &args.record_every,
            &plan.launch.path,
        )?),
        None => None,
    };
    let servers = [args.view.plan()?, args.foxglove.plan()?];
    let mut stack = start(
        args,
        plan,
        recording,
        servers.into_iter().flatten().collect(),
    )?;
    let end = supervise(&mut stack);
    finish(stack, end)
}

/// The launcher's ports on the stack.
struct Ports {
    ctx: Context,
    stats: Subscriber<Stats>,
    status: Subscriber<RunStatus>,
    processes: Publisher<Processes>,
    control: ControlServer,
    /// The operator's pace (operator/pace): a run it holds is not stalled.
    pace: Subscriber<mole_types::Pace>,
}

/// What supervision keeps track of.
struct Watch {
    /// The newest step the monitor reported, and when it came (or supervision last looked
    /// away, for a swap).
    last_step: (u64, Instant),
    /// Roles that announced their ports.
    ready: BTreeSet<String>,
    /// When each role last published statistics.
    last_heard: BTreeMap<String, Instant>,
    hangs: BTreeMap<String, u32>,
    gave_up: BTreeSet<String>,
    swaps: Vec<SwapRecord>,
    collector: StatsCollector,
    /// When the world ended its run (the monitor writes its files next).
    world_done_at: Option<Instant>,
}

impl Watch {
    fn new() -> Self {
        Self {
            last_step: (0, Instant::now()),
            ready: BTreeSet::new(),
            last_heard: BTreeMap::new(),
            hangs: BTreeMap::new(),
            gave_up: BTreeSet::new(),
            swaps: Vec::new(),
            collector: StatsCollector::default(),
            world_done_at: None,
        }
    }

    /// A role's process was restarted: its hang timer starts over from now. The old process's
    /// last statistics are not the new one's: a restart that came late (the supervisor was busy,
    /// e.g. with a swap) would otherwise be killed as hung the moment it started.
    fn restarted(&mut self, role: &str) {
        self.last_heard.insert(role.to_string(), Instant::now());
    }

    /// A process's statistics sample: it is alive (hang detection), ready, and counted.
    fn record(&mut self, s: &Stats) {
        let role = read_name(&s.process).into_owned();
        self.last_heard.insert(role.clone(), Instant::now());
        self.ready.insert(role);
        self.collector.record(s);
    }
}

/// A started stack.
struct Stack<'a> {
    args: &'a UpArgs,
    plan: Plan,
    ports: Ports,
    /// Declared after `supervisor`'s users are done with it: see [`finish`].
    keeper: ResumeKeeper,
    supervisor: Supervisor,
    /// `--record`: the recorder beside the stack.
    recorder: Option<Recorder>,
    /// `--view`, `--foxglove`: the servers beside the stack.
    servers: Vec<SideServer>,
    /// `mole fault`: the faults injected, and the processes a fault holds stopped.
    faults: Injector,
    /// `mole param`: the settings in force, changed while the stack runs.
    tuner: Tuner,
    watch: Watch,
    interrupted: Arc<AtomicBool>,
    progress: ProgressBar,
    started: Instant,
}

fn log_of(args: &UpArgs, role: &str) -> PathBuf {
    args.out.join("logs").join(format!("{role}.log"))
}
