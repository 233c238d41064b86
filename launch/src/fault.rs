//! `mole fault`: one fault into a running stack (kill or stop a role; delay, drop or corrupt a
//! topic's samples for a while), or `mole fault chaos`, a seeded random sequence of them. Each
//! is one `stack/control` request to the running `mole up`, which carries it out and publishes
//! it on `stack/faults` (see `crate::inject`).

use crate::Failure;
use clap::{Args, Subcommand};
use mole_runtime::{CommonArgs, Context, ControlClient, stack_clock_mode};
use mole_types::fault::faultable_topics;
use mole_types::{
    CONTROL_FAULT, CONTROL_OK, CONTROL_REFUSED, ClockMode, ControlRequest, FaultKind, FaultSpec,
    PROCESS_RUNNING, Role, read_name, topics,
};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

#[derive(Debug, Clone, Args)]
pub struct FaultArgs {
    /// Namespace of the running stack.
    #[arg(long, default_value = mole_types::env::DEFAULT_NAMESPACE, global = true)]
    pub namespace: String,
    #[command(subcommand)]
    pub what: FaultCommand,
}

#[derive(Debug, Clone, Subcommand)]
pub enum FaultCommand {
    /// SIGKILL a role's process; its restart policy brings it back.
    Kill {
        /// The role: world, sensing, localization, mapping, planning or monitor.
        role: String,
    },
    /// SIGSTOP a role's process, SIGCONT it after the duration (past 5 s it is found hung).
    Stop {
        role: String,
        /// How long it stays stopped (s).
        #[arg(long = "for", value_name = "SECONDS")]
        duration: f64,
    },
    /// Hold every sample of a topic before its publisher sends it.
    Delay {
        /// A topic a role publishes, e.g. sensing/scan.
        topic: String,
        /// How long each sample is held (ms).
        #[arg(long = "by", value_name = "MS")]
        delay_ms: f64,
        /// How long the delay lasts (s).
        #[arg(long = "for", value_name = "SECONDS")]
        duration: f64,
    },
    /// Drop a fraction of a topic's samples at its publisher (realtime stacks only: lockstep
    /// delivers every sample).
    Drop {
        topic: String,
        /// The fraction of samples dropped, above 0 and at most 1.
        #[arg(long, default_value_t = 1.0)]
        fraction: f64,
        #[arg(long = "for", value_name = "SECONDS")]
        duration: f64,
    },
    /// Corrupt a fraction of a topic's samples so that every reader's validation must refuse
    /// them (lockstep then delivers the good sample after the corrupted one).
    Corrupt {
        topic: String,
        #[arg(long, default_value_t = 1.0)]
        fraction: f64,
        #[arg(long = "for", value_name = "SECONDS")]
        duration: f64,
    },
    /// A seeded random sequence of faults for a while; prints each and a count by kind.
    Chaos(ChaosArgs),
}

#[derive(Debug, Clone, Args)]
pub struct ChaosArgs {
    /// How long to inject faults (s).
    #[arg(long, value_name = "SECONDS")]
    pub duration: f64,
    /// The seed of the sequence: the same seed, the same faults at the same moments.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The mean time between two faults (s).
    #[arg(long, value_name = "SECONDS", default_value_t = 3.0)]
    pub every: f64,
    /// Write every fault and its answer as JSON here.
    #[arg(long, value_name = "FILE")]
    pub json: Option<std::path::PathBuf>,
}

/// The node a chaos session watches the stack's process table on.
const CHAOS_NODE: &str = "fault";
/// How long one fault request may wait for the launcher's answer.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(10);

/// `mole fault ...`.
pub fn fault(args: &FaultArgs) -> Result<(), Failure> {
    let spec = match &args.what {
        FaultCommand::Chaos(chaos) => return run_chaos(&args.namespace, chaos),
        FaultCommand::Kill { role } => spec(FaultKind::Kill, role, 0.0, 0.0, 0.0),
        FaultCommand::Stop { role, duration } => spec(FaultKind::Stop, role, *duration, 0.0, 0.0),
        FaultCommand::Delay {
            topic,
            delay_ms,
            duration,
        } => spec(FaultKind::Delay, topic, *duration, *delay_ms, 0.0),
        FaultCommand::Drop {
            topic,
            fraction,
            duration,
        } => spec(FaultKind::Drop, topic, *duration, 0.0, *fraction),
        FaultCommand::Corrupt {
            topic,
            fraction,
            duration,
        } => spec(FaultKind::Corrupt, topic, *duration, 0.0, *fraction),
    };
    let mode = running_mode(&args.namespace)?;
    spec.check(mode).map_err(|e| Failure::input(e.0))?;
    let client = connect(&args.namespace)?;
    println!("{}", send(&client, &spec)?);
    Ok(())
}

fn spec(kind: FaultKind, target: &str, duration_s: f64, delay_ms: f64, fraction: f64) -> FaultSpec {
    FaultSpec {
        kind,
        target: target.to_owned(),
        duration_s,
        delay_ms,
        fraction,
    }
}

/// The clock mode of the stack in `namespace`; none there is bad input.
fn running_mode(namespace: &str) -> Result<ClockMode, Failure> {
    stack_clock_mode(namespace).ok_or_else(|| {
        Failure::input(format!(
            "no stack runs in namespace `{namespace}` (start one with `mole up --namespace \
             {namespace}`)"
        ))
    })
}

fn connect(namespace: &str) -> Result<ControlClient, Failure> {
    ControlClient::connect(namespace).map_err(|e| Failure::input(e.to_string()))
}

/// How long a chaos session waits, after its last fault, for every role to run again.
const RECOVERY_TIMEOUT: Duration = Duration::from_secs(30);

/// Whether the stack is whole again after a chaos session.
enum Whole {
    /// Every role runs, this long after the wait began.
    Yes(Duration),
    /// The stack is gone.
    Ended,
    /// These roles still do not run after [`RECOVERY_TIMEOUT`].
    No(String),
}

/// Waits until the launcher's process table (`stack/processes`, once a second) shows every role
/// running, in two tables published after the wait began (the first may predate a restart).
fn wait_until_whole(namespace: &str, mode: ClockMode) -> Result<Whole, Failure> {
    let common = CommonArgs::attach(namespace, mode);
    let shutdown = Arc::new(AtomicBool::new(false));
    let attach = |e: mole_runtime::RuntimeError| Failure::run(format!("chaos: {e}"));
    let mut ctx = Context::with_shutdown_flag(CHAOS_NODE, &common, shutdown).map_err(attach)?;
    ctx.silence_stats();
    let mut tables = ctx
        .passive_subscriber(topics::STACK_PROCESSES)
        .map_err(attach)?;
    let start = Instant::now();
    let (mut fresh, mut missing) = (0, String::from("the process table"));
    while start.elapsed() < RECOVERY_TIMEOUT {
        if stack_clock_mode(namespace).is_none() {
            return Ok(Whole::Ended);
        }
        tables.drain(|table| {
            fresh += 1;
            let down: Vec<String> = table
                .processes()
                .iter()
                .filter(|p| p.state != PROCESS_RUNNING)
                .map(|p| read_name(&p.role).into_owned())
                .collect();
            missing = down.join(", ");
        });
        if fresh >= 2 && missing.is_empty() {
            return Ok(Whole::Yes(start.elapsed()));
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    Ok(Whole::No(missing))
}

/// One fault request; the launcher's sentence, or its refusal as bad input.
fn send(client: &ControlClient, spec: &FaultSpec) -> Result<String, Failure> {
    let mut request = ControlRequest::new(CONTROL_FAULT);
    if !request.set_argv(&spec.to_words()) {
        return Err(Failure::input("the fault's target is too long"));
    }
    let response = client
        .call(request, ANSWER_TIMEOUT)
        .map_err(|e| Failure::run(e.to_string()))?;
    let text = read_name(&response.text).into_owned();
    match response.status {
        CONTROL_OK => Ok(text),
        CONTROL_REFUSED => Err(Failure::input(text)),
        _ => Err(Failure::run(text)),
    }
}

/// Roles a chaos session kills and stops: every role but the monitor, which measures the run
/// (killed, it would lose what it measured so far).
const CHAOS_ROLES: [Role; 5] = [
    Role::World,
    Role::Sensing,
    Role::Localization,
    Role::Mapping,
    Role::Planning,
];

/// A chaos session's faults for a stack of clock `mode`: (seconds from its start, fault), from
/// `seed` alone. Kinds are drawn evenly (no drop in lockstep), targets evenly from the roles
/// and from the topics the roles publish but `world/map` (published once, at the start); the
/// time between two faults is exponential with mean `every`, at least half a second.
pub fn chaos_plan(
    seed: u64,
    duration_s: f64,
    every_s: f64,
    mode: ClockMode,
) -> Vec<(f64, FaultSpec)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut draw = move || rng.random::<f64>();
    let kinds: Vec<FaultKind> = FaultKind::ALL
        .iter()
        .copied()
        .filter(|k| !(mode == ClockMode::Lockstep && *k == FaultKind::Drop))
        .collect();
    let topics: Vec<&str> = faultable_topics()
        .into_iter()
        .filter(|t| *t != mole_types::topics::WORLD_MAP.name)
        .collect();
    let pick = |u: f64, n: usize| ((u * n as f64) as usize).min(n - 1);
    let mut plan = Vec::new();
    let mut at = 0.0;
    loop {
        at += (-every_s * (1.0 - draw()).ln()).max(0.5);
        if at >= duration_s {
            return plan;
        }
        let kind = kinds[pick(draw(), kinds.len())];
        let target = match kind.targets_a_role() {
            true => CHAOS_ROLES[pick(draw(), CHAOS_ROLES.len())].name(),
            false => topics[pick(draw(), topics.len())],
        };
        // Rounded to what a user would type: 0.1 s, whole milliseconds, 0.01 of the samples.
        let round = |x: f64, per: f64| (x * per).round() / per;
        let (length, amount) = (round(0.5 + 2.5 * draw(), 10.0), draw());
        let fault = match kind {
            FaultKind::Kill => spec(kind, target, 0.0, 0.0, 0.0),
            FaultKind::Stop => spec(kind, target, length, 0.0, 0.0),
            FaultKind::Delay => spec(kind, target, length, (1.0 + 49.0 * amount).round(), 0.0),
            FaultKind::Drop | FaultKind::Corrupt => spec(
                kind,
                target,
                length,
                0.0,
                round(0.05 + 0.45 * amount, 100.0),
            ),
        };
        plan.push((at, fault));
    }
}

/// `mole fault chaos`: the plan's faults at their moments, until its end or the stack's.
fn run_chaos(namespace: &str, args: &ChaosArgs) -> Result<(), Failure> {
    if !(args.duration.is_finite() && args.duration > 0.0) {
        return Err(Failure::input(format!(
            "--duration: expected seconds above 0, found {}",
            args.duration
        )));
    }
    if !(args.every.is_finite() && args.every > 0.0) {
        return Err(Failure::input(format!(
            "--every: expected seconds above 0, found {}",
            args.every
        )));
    }
    let mode = running_mode(namespace)?;
    let client = connect(namespace)?;
    let plan = chaos_plan(args.seed, args.duration, args.every, mode);
    let start = Instant::now();
    let mut counts: BTreeMap<&str, (u32, u32)> = BTreeMap::new();
    let mut log = Vec::new();
    let mut ended_early = false;
    for (at, spec) in &plan {
        let wait = Duration::from_secs_f64(*at).saturating_sub(start.elapsed());
        std::thread::sleep(wait);
        let answer = send(&client, spec);
        let entry = counts.entry(spec.kind.name()).or_default();
        match &answer {
            Ok(line) => {
                entry.0 += 1;
                println!("{:7.2} s  {line}", start.elapsed().as_secs_f64());
            }
            Err(f) if f.kind == crate::FailureKind::BadInput => {
                entry.1 += 1;
                println!(
                    "{:7.2} s  refused: {}",
                    start.elapsed().as_secs_f64(),
                    f.message
                );
            }
            Err(f) => {
                if stack_clock_mode(namespace).is_none() {
                    ended_early = true;
                    println!(
                        "the stack ended after {:.1} s",
                        start.elapsed().as_secs_f64()
                    );
                    break;
                }
                return Err(Failure::run(format!("chaos: {}", f.message)));
            }
        }
        log.push(serde_json::json!({
            "at_s": at,
            "fault": spec.to_string(),
            "kind": spec.kind.name(),
            "target": spec.target,
            "injected": answer.is_ok(),
            "answer": match &answer { Ok(l) => l.clone(), Err(f) => f.message.clone() },
        }));
    }
    if !ended_early {
        std::thread::sleep(Duration::from_secs_f64(args.duration).saturating_sub(start.elapsed()));
        // A session is over when its last fault is and the stack is whole again.
        let faults_over = plan
            .iter()
            .map(|(at, spec)| at + spec.duration_s)
            .fold(args.duration, f64::max);
        std::thread::sleep(Duration::from_secs_f64(faults_over).saturating_sub(start.elapsed()));
        match wait_until_whole(namespace, mode)? {
            Whole::Yes(after) => println!(
                "{:7.2} s  every role runs again ({:.1} s after the last fault was over)",
                start.elapsed().as_secs_f64(),
                after.as_secs_f64()
            ),
            Whole::Ended => println!(
                "the stack ended after {:.1} s",
                start.elapsed().as_secs_f64()
            ),
            Whole::No(missing) => {
                return Err(Failure::run(format!(
                    "chaos: {RECOVERY_TIMEOUT:?} after the last fault, {missing} still not running"
                )));
            }
        }
    }
    println!(
        "\nfaults (seed {}, {mode}):\n| kind | injected | refused |\n| --- | ---: | ---: |",
        args.seed
    );
    for (kind, (injected, refused)) in &counts {
        println!("| {kind} | {injected} | {refused} |");
    }
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&serde_json::json!({
            "seed": args.seed, "mode": mode.name(), "duration_s": args.duration, "faults": log,
        }))
        .map_err(|e| Failure::run(e.to_string()))?;
        std::fs::write(path, text + "\n")
            .map_err(|e| Failure::run(format!("cannot write {}: {e}", path.display())))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The same seed gives the same faults at the same moments; every fault of a plan passes
    /// the rules of its clock mode, and over a long plan every kind and every chaos role
    /// comes up.
    #[test]
    fn a_chaos_plan_is_its_seeds_and_keeps_the_rules() {
        for mode in [ClockMode::Realtime, ClockMode::Lockstep] {
            let plan = chaos_plan(7, 600.0, 3.0, mode);
            assert_eq!(plan, chaos_plan(7, 600.0, 3.0, mode));
            assert_ne!(plan, chaos_plan(8, 600.0, 3.0, mode));
            assert!(
                (120..=240).contains(&plan.len()),
                "{} faults in 600 s",
                plan.len()
            );
            for (at, fault) in &plan {
                assert!((0.5..600.0).contains(at));
                assert_eq!(fault.check(mode), Ok(()), "{fault}");
            }
            for pair in plan.windows(2) {
                assert!(pair[1].0 - pair[0].0 >= 0.5, "faults at least 0.5 s apart");
            }
            for kind in FaultKind::ALL {
                let n = plan.iter().filter(|(_, f)| f.kind == *kind).count();
                match (mode, kind) {
                    (ClockMode::Lockstep, FaultKind::Drop) => assert_eq!(n, 0),
                    _ => assert!(n > 0, "{kind} in {mode}"),
                }
            }
            for role in CHAOS_ROLES {
                assert!(plan.iter().any(|(_, f)| f.target == role.name()), "{role}");
            }
            assert!(plan.iter().all(|(_, f)| f.target != Role::Monitor.name()));
        }
    }
}
