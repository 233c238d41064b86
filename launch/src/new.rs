//! `mole new planner|estimator|observer NAME [DIR]`: a planner, an estimator or an observer in a
//! crate of its own, outside mole's workspace, that builds on its own. A planner or an estimator
//! runs in its role (`mole up --swap planning=DIR/NAME/target/release/NAME`, `--swap
//! localization=…`); an observer beside a running stack (`DIR/NAME/target/release/NAME
//! --namespace NS`). It depends on mole's runtime and message crates (and a planner on the
//! planning crate's `Planner`) by path (this checkout's, or `--mole`'s).

use crate::Failure;
use clap::{Args, ValueEnum};
use std::path::{Path, PathBuf};

/// What kind of process to make.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Kind {
    /// A planner in the planning role: pose, scan, touch, grid and goal in; command and status out.
    Planner,
    /// An estimator in the localization role: odometry, beacons, fix and touch in; pose out.
    Estimator,
    /// An observer beside a running stack, in no role: truth and pose in, the position error
    /// out when the run ends.
    Observer,
}

impl Kind {
    /// How to run it, once built into `program`.
    fn how_to_run(self, program: &str) -> String {
        match self {
            Kind::Planner => format!("mole up --swap planning={program}"),
            Kind::Estimator => format!("mole up --swap localization={program}"),
            Kind::Observer => format!("{program} --namespace robot0   (beside `mole up`)"),
        }
    }

    fn article(self) -> &'static str {
        match self {
            Kind::Planner => "a planner",
            Kind::Estimator => "an estimator",
            Kind::Observer => "an observer",
        }
    }

    /// The crate's main, `{name}` to be replaced.
    fn main(self) -> &'static str {
        match self {
            Kind::Planner => PLANNER_MAIN,
            Kind::Estimator => ESTIMATOR_MAIN,
            Kind::Observer => OBSERVER_MAIN,
        }
    }

    /// mole's crates it depends on, by their folders.
    fn depends_on(self) -> &'static [(&'static str, &'static str)] {
        match self {
            Kind::Planner => &[
                ("mole-runtime", "processes/runtime"),
                ("mole-types", "shared-types"),
                ("mole-planning", "processes/planning"),
            ],
            Kind::Estimator | Kind::Observer => &[
                ("mole-runtime", "processes/runtime"),
                ("mole-types", "shared-types"),
            ],
        }
    }
}

#[derive(Debug, Clone, Args)]
pub struct NewArgs {
    pub kind: Kind,
    /// The crate's name, also its program's: lowercase letters, digits, `-` and `_`.
    pub name: String,
    /// Where to make it (DIR/NAME); the current directory by default.
    pub dir: Option<PathBuf>,
    /// The mole checkout whose crates it depends on; the one `mole` was built from by default.
    #[arg(long)]
    pub mole: Option<PathBuf>,
}

/// The checkout this `mole` was built from.
fn this_checkout() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_default()
}

/// `mole new`: writes the crate and says how to build and run it.
pub fn new(args: &NewArgs) -> Result<(), Failure> {
    let name = &args.name;
    let valid = |c: char| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-' || c == '_';
    if name.is_empty()
        || !name.chars().all(valid)
        || !name.starts_with(|c: char| c.is_ascii_lowercase())
    {
        return Err(Failure::input(format!(
            "mole new: `{name}`: expected a crate name of lowercase letters, digits, `-` and `_`, \
             starting with a letter"
        )));
    }
    let mole = args.mole.clone().unwrap_or_else(this_checkout);
    let mole = mole
        .canonicalize()
        .map_err(|e| Failure::input(format!("mole new: --mole {}: {e}", mole.display())))?;
    if !mole.join("processes/runtime/Cargo.toml").is_file() {
        return Err(Failure::input(format!(
            "mole new: {} is not a mole checkout (expected processes/runtime/Cargo.toml in it)",
            mole.display()
        )));
    }
    let dir = args
        .dir
        .clone()
        .unwrap_or_else(|| PathBuf::from("."))
        .join(name);
    if dir.exists() {
        return Err(Failure::input(format!(
            "mole new: {} exists already: choose another name or directory",
            dir.display()
        )));
    }
    let files = crate_files(args.kind, name, &mole);
    for (path, text) in &files {
        let path = dir.join(path);
        let written = path
            .parent()
            .map_or(Ok(()), std::fs::create_dir_all)
            .and_then(|()| std::fs::write(&path, text));
        written
            .map_err(|e| Failure::run(format!("mole new: cannot write {}: {e}", path.display())))?;
    }
    // The workspace's lock file: the crate builds with the versions mole was tested with.
    let lock = mole.join("Cargo.lock");
    if lock.is_file() {
        let _ = std::fs::copy(&lock, dir.join("Cargo.lock"));
    }
    let program = format!("{}/target/release/{name}", dir.display());
    println!(
        "{}: {} crate. Build and run it:\n  cargo build --release --manifest-path {}/Cargo.toml\n  {}",
        dir.display(),
        args.kind.article(),
        dir.display(),
        args.kind.how_to_run(&program)
    );
    Ok(())
}

/// The files of a `kind` crate named `name` on the mole checkout `mole`.
pub fn crate_files(kind: Kind, name: &str, mole: &Path) -> Vec<(&'static str, String)> {
    let dependencies: String = kind
        .depends_on()
        .iter()
        .map(|(krate, folder)| {
            format!(
                "{krate} = {{ path = \"{}\" }}\n",
                mole.join(folder).display()
            )
        })
        .collect();
    let manifest = format!(
        r#"[package]
name = "{name}"
version = "0.1.0"
edition = "2024"

[dependencies]
{dependencies}clap = {{ version = "4", features = ["derive", "env"] }}

# A crate of its own, not a member of mole's workspace.
[workspace]
"#
    );
    vec![
        ("Cargo.toml", manifest),
        ("src/main.rs", kind.main().replace("{name}", name)),
        (".gitignore", "/target\n".to_string()),
    ]
}

/// A planner process: the planning role's ports (mole's graph), a planner that drives straight
/// and turns in place while something is close ahead.
const PLANNER_MAIN: &str = r#"//! {name}: a planner in the planning role of a mole stack.
//!     cargo build --release && mole up --swap planning=target/release/{name}

use clap::Parser;
use mole_planning::{Command, Planner, PlannerInput, RobotLimits};
use mole_runtime::{CommonArgs, Order, Process, Rule};
use mole_types::{MODE_EXPLORE, PlannerKind, Pose2, Role, topics};

#[derive(Debug, Parser)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
}

/// Drives straight at half speed; turns left in place while the lidar sees something closer than
/// 0.6 m within 0.4 rad of straight ahead.
#[derive(Debug)]
struct Cautious {
    limits: RobotLimits,
}

impl Planner for Cautious {
    fn kind(&self) -> PlannerKind {
        PlannerKind::RandomWalk
    }

    fn step(&mut self, input: &PlannerInput) -> Command {
        let ahead = |(i, &r): (usize, &f32), scan: &mole_types::Scan| {
            let angle = scan.angle_min + i as f32 * scan.angle_increment;
            angle.abs() < 0.4 && r < 0.6
        };
        let blocked = input
            .scan
            .is_some_and(|s| s.ranges().iter().enumerate().any(|b| ahead(b, s)));
        let (v, omega) = match blocked {
            true => (0.0, 0.5 * self.limits.max_omega),
            false => (0.5 * self.limits.max_speed, 0.0),
        };
        Command { v, omega, mode: MODE_EXPLORE }
    }
}

fn main() -> std::process::ExitCode {
    let args = Args::parse();
    mole_runtime::run_role(Role::Planning, &args.common, run)
}

/// The planning role's ports, as mole's graph has them: the pose triggers a step.
fn run(mut p: Process) -> Result<(), Box<dyn std::error::Error>> {
    let pose = p.trigger(topics::LOCALIZATION_POSE, Order::Newest)?;
    let scan = p.input(topics::SENSING_SCAN, Rule::SameTick)?;
    let tactile = p.input(topics::SENSING_TACTILE, Rule::SameTick)?;
    let grid = p.input(topics::MAPPING_GRID, Rule::PreviousTick)?;
    let _goal = p.input(topics::OPERATOR_GOAL, Rule::Newest)?;
    let mut cmd_out = p.output(topics::PLANNING_CMD)?;
    let mut status_out = p.output(topics::PLANNING_STATUS)?;
    p.run(
        |start| {
            let limits = RobotLimits::from(&start.map.robot).sanitized();
            Ok((Cautious { limits }, Command::STOP, start.map.dt))
        },
        |(planner, last, dt), step| {
            let at = step.trigger(pose);
            let command = planner.step(&PlannerInput {
                tick: step.tick(),
                dt: *dt,
                pose: Pose2::new(at.x, at.y, at.theta),
                scan: step.get(scan),
                tactile: step.get(tactile),
                grid: step.get(grid),
                last_command: *last,
            });
            *last = command;
            let (k, origin) = (step.tick(), step.origin_ns());
            cmd_out.publish(k, origin, |c| (c.v, c.omega, c.mode, c._pad) = (command.v, command.omega, command.mode, 0))?;
            status_out.publish(k, origin, |s| {
                planner.write_status(s);
                s.mode = command.mode;
            })?;
            Ok(())
        },
    )
}
"#;

/// An estimator process: the localization role's ports (mole's graph), dead reckoning from the
/// start pose with a variance that grows with the distance and the turn driven.
const ESTIMATOR_MAIN: &str = r#"//! {name}: an estimator in the localization role of a mole stack.
//!     cargo build --release && mole up --swap localization=target/release/{name}

use clap::Parser;
use mole_runtime::{CommonArgs, Order, Process, Rule};
use mole_types::{EstimatorKind, Odom, Role, topics};

#[derive(Debug, Parser)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
}

/// Dead reckoning: the unicycle driven by the measured odometry from the start pose; its
/// variance grows with the distance (m²/m) and the turn (rad²/rad) driven.
#[derive(Debug)]
struct DeadReckoning {
    pose: [f64; 3],
    variance: [f64; 3],
}

impl DeadReckoning {
    const PER_METRE: f64 = 0.01;
    const PER_RADIAN: f64 = 0.01;

    fn step(&mut self, odom: &Odom) {
        let [x, y, theta] = &mut self.pose;
        let (distance, turn) = (odom.v * odom.dt, odom.omega * odom.dt);
        *x += distance * theta.cos();
        *y += distance * theta.sin();
        *theta = (*theta + turn + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
        self.variance[0] += Self::PER_METRE * distance.abs();
        self.variance[1] += Self::PER_METRE * distance.abs();
        self.variance[2] += Self::PER_RADIAN * turn.abs();
    }
}

fn main() -> std::process::ExitCode {
    let args = Args::parse();
    mole_runtime::run_role(Role::Localization, &args.common, run)
}

/// The localization role's ports, as mole's graph has them: odometry triggers a step.
fn run(mut p: Process) -> Result<(), Box<dyn std::error::Error>> {
    let odom = p.trigger(topics::SENSING_ODOM, Order::Newest)?;
    let _beacons = p.input(topics::SENSING_BEACONS, Rule::SameTick)?;
    let _fix = p.input(topics::SENSING_FIX, Rule::SameTick)?;
    let _tactile = p.input(topics::SENSING_TACTILE, Rule::SameTick)?;
    let mut pose_out = p.output(topics::LOCALIZATION_POSE)?;
    let _particles = p.output(topics::LOCALIZATION_PARTICLES)?;
    let _landmarks = p.output(topics::LOCALIZATION_LANDMARKS)?;
    let _trajectory = p.output(topics::LOCALIZATION_TRAJECTORY)?;
    p.run(
        |start| {
            let map = start.map;
            let pose = [map.start_x, map.start_y, map.start_theta];
            Ok(DeadReckoning { pose, variance: [0.0; 3] })
        },
        |estimate, step| {
            let measured = step.trigger(odom);
            estimate.step(measured);
            let (k, origin) = (step.tick(), step.origin_ns());
            pose_out.publish(k, origin, |out| {
                [out.x, out.y, out.theta] = estimate.pose;
                out.covariance = [0.0; 9];
                for i in 0..3 {
                    out.covariance[4 * i] = estimate.variance[i];
                }
                out.odom = [measured.x, measured.y, measured.theta];
                // The graph's estimators are a closed list: it reports itself as a Kalman filter.
                out.estimator = EstimatorKind::Kf.code();
            })?;
            Ok(())
        },
    )
}
"#;

/// An observer process: beside a stack, in no role; the root mean square of the estimate's
/// position error over the steps it read, printed as JSON when the run ends.
const OBSERVER_MAIN: &str = r##"//! {name}: an observer beside a mole stack: it reads the truth and the estimate of every step
//! and, when the run ends (or at Ctrl-C), prints the estimate's position error as JSON.
//!     cargo build --release && target/release/{name} --namespace robot0   (beside `mole up`)

use clap::Parser;
use mole_runtime::{CommonArgs, Context, Wake, stack_clock_mode};
use mole_types::topics;
use std::collections::BTreeMap;

#[derive(Debug, Parser)]
struct Args {
    /// The namespace of the running stack.
    #[arg(long, default_value = "robot0")]
    namespace: String,
}

/// The root mean square of the position error over the steps whose truth and estimate it read.
#[derive(Debug, Default)]
struct PositionError {
    truths: BTreeMap<u64, (f64, f64)>,
    estimates: BTreeMap<u64, (f64, f64)>,
    first_tick: Option<u64>,
    last_tick: u64,
    squared_sum: f64,
    samples: u64,
}

impl PositionError {
    /// Scores every step both have come for; forgets them.
    fn match_steps(&mut self) {
        let both: Vec<u64> = self.estimates.keys().filter(|k| self.truths.contains_key(k)).copied().collect();
        for tick in both {
            let ((x, y), (tx, ty)) = (self.estimates[&tick], self.truths[&tick]);
            self.squared_sum += (x - tx).powi(2) + (y - ty).powi(2);
            self.samples += 1;
            self.first_tick.get_or_insert(tick);
            self.last_tick = tick;
            self.estimates.remove(&tick);
        }
        // A truth whose estimate never came is not waited for long.
        let newest = self.truths.keys().next_back().copied().unwrap_or(0);
        self.truths.retain(|&tick, _| tick + 100 > newest);
    }
}

fn main() -> std::process::ExitCode {
    mole_runtime::exit_code(run(&Args::parse()))
}

fn run(args: &Args) -> Result<(), Box<dyn std::error::Error>> {
    let mode = stack_clock_mode(&args.namespace)
        .ok_or_else(|| format!("no stack runs in the namespace `{}`", args.namespace))?;
    let mut ctx = Context::new("{name}", &CommonArgs::attach(&args.namespace, mode))?;
    ctx.silence_stats();
    // Woken by every truth: in lockstep a queue it left unread would hold the stack up.
    let mut truths = ctx.subscriber(topics::WORLD_TRUTH)?;
    let mut estimates = ctx.passive_subscriber(topics::LOCALIZATION_POSE)?;
    let waitset = ctx.waitset()?;
    let wakers = [truths.waker()];
    let _attached = waitset.attach_all(&wakers)?;
    ctx.ready();
    let (mut error, mut ended) = (PositionError::default(), false);
    while !ended {
        let wake = waitset.wait(&mut ctx, None)?;
        truths.drain(|t| {
            error.truths.insert(t.header.tick, (t.x, t.y));
            ended |= t.is_end();
        });
        estimates.drain(|p| _ = error.estimates.insert(p.header.tick, (p.x, p.y)));
        error.match_steps();
        ended |= wake == Wake::Shutdown;
    }
    let rmse = (error.squared_sum / error.samples.max(1) as f64).sqrt();
    let first = error.first_tick.unwrap_or(0);
    let (samples, last) = (error.samples, error.last_tick);
    println!(r#"{{"samples":{samples},"first_tick":{first},"last_tick":{last},"rmse_m":{rmse}}}"#);
    Ok(())
}
"##;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_planner_crate_depends_on_the_checkout_by_path_and_names_its_program() {
        let files = crate_files(Kind::Planner, "careful", Path::new("/src/mole"));
        let manifest = &files[0].1;
        assert!(manifest.contains("name = \"careful\""));
        assert!(manifest.contains("mole-runtime = { path = \"/src/mole/processes/runtime\" }"));
        assert!(
            manifest.contains("\n[workspace]\n"),
            "a workspace of its own"
        );
        assert!(files[1].1.starts_with("//! careful: a planner"));
    }
}
