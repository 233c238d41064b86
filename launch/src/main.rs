//! `mole`: starts the stack with one command, supervises it, and measures it.

use clap::{Parser, Subcommand};
use mole_launch::bench::{BenchCommand, bench};
use mole_launch::control::{NamespaceArgs, SwapArgs, status, stop, swap};
use mole_launch::doctor::{DoctorArgs, doctor};
use mole_launch::eval::{EvalArgs, eval};
use mole_launch::export::{ExportArgs, export};
use mole_launch::fault::{FaultArgs, fault};
use mole_launch::g2o::{G2oArgs, g2o};
use mole_launch::new::{NewArgs, new};
use mole_launch::param::{ParamArgs, param};
use mole_launch::record::{InfoArgs, RecordArgs, info, record};
use mole_launch::replay::{ReplayArgs, replay};
use mole_launch::servers::{FOXGLOVE, VIEW, ViewArgs, view};
use mole_launch::top::{TopArgs, top};
use mole_launch::up::{UpArgs, up};
use std::process::ExitCode;

/// Start, supervise and measure the mole robot stack
#[derive(Debug, Parser)]
#[command(name = "mole", version)]
struct Cli {
    #[command(subcommand)]
    command: MoleCommand,
}

#[derive(Debug, Subcommand)]
enum MoleCommand {
    /// Start the stack, show progress, stop when done or on Ctrl-C, write summary.json and map.png.
    Up(UpArgs),
    /// Replace one process of a running stack (sensing, localization, mapping or planning) by
    /// another command while the rest runs; reports the gap.
    Swap(SwapArgs),
    /// Stop a running stack as Ctrl-C would (it writes its summary).
    Stop(NamespaceArgs),
    /// One line on a running stack: tick, mode, each process's pid and state.
    Status(NamespaceArgs),
    /// Inject a fault into a running stack: kill or stop a role, delay, drop or corrupt a
    /// topic's samples, or a seeded chaos session of them.
    Fault(FaultArgs),
    /// List, get or set the settings of a running stack's processes (docs/settings.md).
    Param(ParamArgs),
    /// Watch a running stack: each topic's rate, latency, drops; each process's state and CPU.
    Top(TopArgs),
    /// Record every topic of a running stack into an MCAP file, until Ctrl-C or the stack ends.
    Record(RecordArgs),
    /// Run a recorded stack again with its recorded roles (default world,sensing) played back
    /// from the file; --check compares the live roles' outputs with the recording's.
    Replay(ReplayArgs),
    /// Serve a live view of a running stack (or of a recording FILE, with a timeline) in a
    /// browser, until Ctrl-C or the stack ends.
    View(ViewArgs),
    /// Serve a running stack (or a recording FILE) to the Foxglove app or Lichtblick.
    Foxglove(ViewArgs),
    /// Describe a recording: duration, ticks, topics with counts and rates, metadata.
    Info(InfoArgs),
    /// Write a recording again for other tools: with Foxglove's well-known schemas (JSON), so
    /// Foxglove or Lichtblick shows it without a plug-in, or as a ROS 2 bag (CDR).
    Export(ExportArgs),
    /// Run a planner and estimator over a family of generated worlds (lockstep, parallel jobs)
    /// and report success, coverage, errors and consistency with 95% intervals.
    Eval(EvalArgs),
    /// Optimise a 2-D g2o pose graph (VERTEX_SE2, VERTEX_XY, EDGE_SE2, EDGE_SE2_XY) with
    /// GraphSLAM's solver; report the error before and after, optionally write the optimum.
    G2o(G2oArgs),
    /// Measure latency and throughput.
    #[command(subcommand)]
    Bench(BenchCommand),
    /// Check this machine for what makes iceoryx2 stacks fail (shared memory, iceoryx2's
    /// directory, what killed processes left, other users' stacks, containers, the clock, limits)
    /// and say how to fix each; exit 1 when something is wrong.
    Doctor(DoctorArgs),
    /// Make a planner in a crate of its own, to run in its role with `mole up --swap`.
    New(NewArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    mole_runtime::init_tracing("mole");
    let result = match cli.command {
        MoleCommand::Up(args) => up(&args).map(drop),
        MoleCommand::Swap(args) => swap(&args),
        MoleCommand::Stop(args) => stop(&args),
        MoleCommand::Status(args) => status(&args),
        MoleCommand::Fault(args) => fault(&args),
        MoleCommand::Param(args) => param(&args),
        MoleCommand::Eval(args) => eval(&args),
        MoleCommand::G2o(args) => g2o(&args),
        MoleCommand::Top(args) => top(&args),
        MoleCommand::Record(args) => record(&args),
        MoleCommand::Replay(args) => replay(&args),
        MoleCommand::View(args) => view(VIEW, &args),
        MoleCommand::Foxglove(args) => view(FOXGLOVE, &args),
        MoleCommand::Info(args) => info(&args),
        MoleCommand::Export(args) => export(&args),
        MoleCommand::Bench(command) => bench(&command),
        MoleCommand::Doctor(args) => doctor(&args),
        MoleCommand::New(args) => new(&args),
    };
    mole_launch::Failure::exit(result)
}
