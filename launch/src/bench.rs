//! `mole bench`: latency and throughput, of the transport alone or of the whole stack.

use crate::Failure;
use crate::bench_ipc::{BenchIpcArgs, bench_ipc};
use crate::bench_peers::{BenchPeersArgs, bench_peers};
use crate::bench_stack::{BenchStackArgs, bench_stack};
use clap::Subcommand;

/// What `mole bench` measures.
#[derive(Debug, Subcommand)]
pub enum BenchCommand {
    /// Latency, throughput, fan-out and a five-hop chain: the runtime, raw iceoryx2, a Unix
    /// socket and TCP, payloads from 64 B to 4 MiB.
    Ipc(BenchIpcArgs),
    /// Run the full stack and report steps/s, loop latency, per-hop latency, CPU and memory.
    Stack(Box<BenchStackArgs>),
    /// The same four-process loop (a source, two stages, a sink back to the source) on raw
    /// iceoryx2, mole's runtime and dora-rs: loop latency, loops/s flat out, CPU per loop.
    Peers(BenchPeersArgs),
}

/// Runs the benchmark `command` names and prints its report.
pub fn bench(command: &BenchCommand) -> Result<(), Failure> {
    match command {
        BenchCommand::Ipc(args) => bench_ipc(args).map(drop),
        BenchCommand::Stack(args) => bench_stack(args).map(drop),
        BenchCommand::Peers(args) => bench_peers(args).map(drop),
    }
}
