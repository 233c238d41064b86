//! `mole bench ipc`: how fast mole's messages move between processes.
//!
//! The driver ([`run_ipc_bench`], called by `mole bench ipc`) spawns probe processes
//! (`mole-bench-probe`, [`PROBE_BINARY`]) and measures, over four transports (mole-runtime, raw
//! iceoryx2, a Unix socket, TCP on loopback):
//! - one-way latency per payload size, ping-pong paced, busy polling and event wake-up; the cost
//!   of writing the payload reported apart from the hand-off (loan → send → receive);
//! - throughput with one publisher flat out;
//! - fan-out latency to the last of 1, 2, 4, 8 subscribers;
//! - a five-hop event chain, flat out and paced at 100 Hz;
//! - the floor under them all: a plain pipe wake-up between two processes, on the same CPU and
//!   on two CPUs, flat out and paced at 100 Hz.
//!
//! Every sample is kept (no filtering); send and receive times are CLOCK_MONOTONIC on the same
//! machine. This crate is, with mole-runtime, the one place that names iceoryx2 types.
//!
//! It also measures how the whole stack's cost grows (`scripts/cost-growth.sh`): `mole-observer`
//! ([`observer`]) reads every topic, `mole-plot` ([`cost`]) gathers the points and draws them.

pub mod canvas;
pub mod cost;
mod driver;
mod floor;
mod link;
pub mod messages;
pub mod observer;
pub mod peers;
mod probe;
mod report;
mod roles;
mod summary;

pub use driver::{find_probe, live_bench_nodes, run_ipc_bench};
pub use floor::Placement;
pub use probe::{ProbeArgs, run_probe};
pub use report::{format_table, print_table, render_svg, write_plot};
pub use summary::Summary;

use serde::Serialize;
use std::path::PathBuf;

/// The probe binary the driver spawns, looked up next to the current executable first.
pub const PROBE_BINARY: &str = "mole-bench-probe";

/// What can go wrong in a benchmark run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error(
        "unsupported payload size {0} B: the sizes are 64, 1024, 4096, 16384, 262144, 1048576 and 4194304"
    )]
    UnsupportedSize(usize),
    #[error("invalid benchmark configuration: {0}")]
    Config(String),
    #[error("cannot find the probe binary `{PROBE_BINARY}` (looked in {0})")]
    ProbeNotFound(String),
    #[error("cannot start a probe process: {0}")]
    Spawn(std::io::Error),
    #[error("a probe failed: {0}")]
    Probe(String),
    #[error("the probes did not start: {0}")]
    Startup(String),
    #[error("timed out: {0}")]
    Timeout(String),
    #[error(transparent)]
    Runtime(#[from] mole_runtime::RuntimeError),
    #[error("iceoryx2: {0}")]
    Iceoryx(String),
    #[error("{what}: {source}")]
    Io {
        what: &'static str,
        source: std::io::Error,
    },
    #[error("internal error: {0}")]
    Internal(String),
}

/// How messages travel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Transport {
    /// mole-runtime: the code path the stack uses.
    Runtime,
    /// iceoryx2 publish-subscribe + event, without the runtime.
    Raw,
    /// A Unix domain stream socket.
    Unix,
    /// TCP on 127.0.0.1 with TCP_NODELAY.
    Tcp,
    /// A pipe each way between two processes (one write wakes a blocking read): the OS
    /// wake-up floor.
    Pipe,
}

impl Transport {
    /// The name in tables and plots.
    pub fn as_str(self) -> &'static str {
        match self {
            Transport::Runtime => "runtime",
            Transport::Raw => "raw iceoryx2",
            Transport::Unix => "unix socket",
            Transport::Tcp => "tcp",
            Transport::Pipe => "pipe",
        }
    }
    /// Whether this is a shared-memory transport (has both wake-up modes).
    pub fn is_ipc(self) -> bool {
        matches!(self, Transport::Runtime | Transport::Raw)
    }
}

/// How a receiver learns that a message arrived.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum WakeMode {
    /// Spins on a non-blocking receive.
    Busy,
    /// Sleeps in a WaitSet until the publisher's event.
    Event,
    /// A blocking read (sockets and pipes only).
    Blocking,
}

impl WakeMode {
    /// The name in tables and plots.
    pub fn as_str(self) -> &'static str {
        match self {
            WakeMode::Busy => "busy",
            WakeMode::Event => "event",
            WakeMode::Blocking => "blocking",
        }
    }
}

/// Which measurement a probe takes part in (decides its ports and its role).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ProbeKind {
    /// Echo every message's receipt (ping-pong latency).
    Latency,
    /// Echo receipts, one of several subscribers.
    Fanout,
    /// Count messages, report totals at the end.
    Throughput,
    /// Republish every message on the next topic of the chain.
    Chain,
    /// Republish every message on the next topic of `mole bench peers`' loop (the last stage
    /// closes it back to the driver).
    Loop,
}

/// What `mole bench ipc` measures. [`IpcBenchConfig::default`] is the full run,
/// [`IpcBenchConfig::quick`] a short one for tests.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IpcBenchConfig {
    /// Base of every probe group's namespace (each group gets `<namespace>-<n>`).
    pub namespace: String,
    /// Payload sizes in bytes (whole message, 32-byte header included); each must be one of
    /// [`messages::SUPPORTED_SIZES`].
    pub sizes: Vec<usize>,
    /// Measured messages per latency point below 1 MiB.
    pub samples: usize,
    /// Measured messages per latency point at 1 MiB and above.
    pub samples_large: usize,
    /// How long each throughput point publishes (s).
    pub throughput_secs: f64,
    /// Subscriber counts for fan-out (each 1..=8).
    pub fanout: Vec<usize>,
    /// Payload size of the fan-out and chain messages (bytes).
    pub fanout_size: usize,
    /// Measured messages per fan-out point.
    pub fanout_samples: usize,
    /// Measured messages through the chain flat out.
    pub chain_samples: usize,
    /// Measured messages through the chain when paced.
    pub chain_paced_samples: usize,
    /// The paced chain's rate (Hz).
    pub chain_rate_hz: f64,
    /// Measured wake-ups per floor point flat out.
    pub floor_samples: usize,
    /// Measured wake-ups per floor point when paced.
    pub floor_paced_samples: usize,
    /// The paced floor's rate (Hz): the driver sleeps until the next slot, then wakes the probe.
    pub floor_rate_hz: f64,
    /// How long to wait for one acknowledgement before giving up (ms).
    pub timeout_ms: u64,
    /// The probe binary; found next to the current executable when `None`.
    pub probe: Option<PathBuf>,
}

impl Default for IpcBenchConfig {
    fn default() -> Self {
        IpcBenchConfig {
            namespace: format!("bench{}", std::process::id()),
            sizes: messages::IPC_SIZES.to_vec(),
            samples: 2000,
            samples_large: 300,
            throughput_secs: 1.0,
            fanout: vec![1, 2, 4, 8],
            fanout_size: 64,
            fanout_samples: 1000,
            chain_samples: 2000,
            chain_paced_samples: 300,
            chain_rate_hz: 100.0,
            floor_samples: 2000,
            floor_paced_samples: 300,
            floor_rate_hz: 100.0,
            timeout_ms: 5000,
            probe: None,
        }
    }
}

impl IpcBenchConfig {
    /// A short run: sizes 64 B and 1 MiB, few samples, fan-out 1 and 2, short throughput, every
    /// floor point.
    pub fn quick() -> Self {
        IpcBenchConfig {
            sizes: vec![64, 1 << 20],
            samples: 50,
            samples_large: 20,
            throughput_secs: 0.1,
            fanout: vec![1, 2],
            fanout_samples: 30,
            chain_samples: 30,
            chain_paced_samples: 10,
            floor_samples: 50,
            floor_paced_samples: 10,
            ..IpcBenchConfig::default()
        }
    }

    /// Measured messages per latency point of `size` bytes.
    pub fn samples_for(&self, size: usize) -> usize {
        if size >= 1 << 20 {
            self.samples_large
        } else {
            self.samples
        }
    }

    /// Refuses what cannot run, before any process starts.
    pub fn validate(&self) -> Result<(), BenchError> {
        if let Some(&bad) = self
            .sizes
            .iter()
            .chain(core::iter::once(&self.fanout_size))
            .find(|s| !messages::is_supported(**s))
        {
            return Err(BenchError::UnsupportedSize(bad));
        }
        let fail = |why: &str| Err(BenchError::Config(why.to_string()));
        if self.sizes.is_empty() {
            return fail("no payload size selected");
        }
        if self.samples == 0
            || self.samples_large == 0
            || self.fanout_samples == 0
            || self.chain_samples == 0
            || self.chain_paced_samples == 0
            || self.floor_samples == 0
            || self.floor_paced_samples == 0
        {
            return fail("every sample count must be at least 1");
        }
        if !(self.throughput_secs.is_finite() && self.throughput_secs > 0.0) {
            return fail("the throughput duration must be positive");
        }
        if !(self.chain_rate_hz.is_finite() && self.chain_rate_hz > 0.0) {
            return fail("the chain rate must be positive");
        }
        if !(self.floor_rate_hz.is_finite() && self.floor_rate_hz > 0.0) {
            return fail("the floor rate must be positive");
        }
        if self.fanout.iter().any(|&n| n == 0 || n > MAX_FANOUT) {
            return fail("fan-out subscriber counts must be within 1..=8");
        }
        if self.timeout_ms == 0 {
            return fail("the timeout must be positive");
        }
        let ns_ok = !self.namespace.is_empty()
            && self.namespace.len() <= 64
            && self
                .namespace
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
        if !ns_ok {
            return fail("the namespace must be 1–64 characters of [A-Za-z0-9_-]");
        }
        Ok(())
    }
}

/// Most fan-out subscribers.
pub const MAX_FANOUT: usize = 8;

/// One-way latency of one transport, wake-up mode and size.
#[derive(Debug, Clone, Serialize)]
pub struct LatencyPoint {
    pub transport: Transport,
    pub wake: WakeMode,
    /// Message size (bytes).
    pub size: usize,
    /// send → receive: stamped after the payload was written, right before the send.
    pub latency: Summary,
    /// loan → send → receive (for sockets the same as `latency`: there is no loan, the copy
    /// through the kernel is in the send).
    pub handoff: Summary,
    /// Writing the payload's bytes into the loan (sockets: into the user buffer).
    pub fill: Summary,
}

/// One publisher flat out for a fixed time.
#[derive(Debug, Clone, Serialize)]
pub struct ThroughputPoint {
    pub transport: Transport,
    pub size: usize,
    /// Messages published.
    pub sent: u64,
    /// Messages the subscriber received (the runtime and iceoryx2 drop the oldest when the
    /// subscriber falls behind; sockets block the sender instead).
    pub received: u64,
    /// Published messages per second.
    pub sent_per_s: f64,
    /// Received messages per second (first to last receipt).
    pub received_per_s: f64,
    /// Received messages × size per second. The publisher writes only the header (the
    /// hand-off is measured, not memory bandwidth), so for the shared-memory transports this is
    /// bytes made available to the subscriber, not bytes copied.
    pub bytes_per_s: f64,
}

/// Latency from one publisher to the last of `subscribers` probes.
#[derive(Debug, Clone, Serialize)]
pub struct FanoutPoint {
    pub transport: Transport,
    pub subscribers: usize,
    pub size: usize,
    pub latency: Summary,
}

/// Latency through five probe processes, each woken by an event and republishing.
#[derive(Debug, Clone, Serialize)]
pub struct ChainPoint {
    pub transport: Transport,
    pub hops: usize,
    /// `None`: flat out (the next message right after the previous came out); else the rate.
    pub rate_hz: Option<f64>,
    /// Driver's loan → last hop's receipt, as seen by the driver.
    pub latency: Summary,
}

/// One process waking another through a pipe (ping-pong: the probe echoes the moment its
/// blocking read returned): the floor under every event-woken transport.
#[derive(Debug, Clone, Serialize)]
pub struct FloorPoint {
    /// Always [`Transport::Pipe`].
    pub transport: Transport,
    /// Where the driver (the waker) and the probe (the sleeper) ran.
    pub placement: Placement,
    /// `None`: flat out (the next wake-up right after the echo came back); else the rate, the
    /// driver sleeping until the next slot before each wake-up.
    pub rate_hz: Option<f64>,
    /// The CPUs (driver, probe) were pinned to; `None` when pinning was refused.
    pub cpus: Option<[usize; 2]>,
    /// Why both ran unpinned (the row still measures, wherever the scheduler put them).
    pub unpinned: Option<String>,
    /// Driver's write → the probe's read returned.
    pub latency: Summary,
}

/// A named ratio of two p50s.
#[derive(Debug, Clone, Serialize)]
pub struct Ratio {
    /// What is divided by what.
    pub what: String,
    pub value: f64,
}

/// Everything one run measured.
#[derive(Debug, Clone, Serialize)]
pub struct IpcReport {
    pub config: IpcBenchConfig,
    /// Logical CPUs of this machine.
    pub cpus: usize,
    pub latency: Vec<LatencyPoint>,
    pub throughput: Vec<ThroughputPoint>,
    pub fanout: Vec<FanoutPoint>,
    pub chain: Vec<ChainPoint>,
    /// The pipe wake-up floor: same CPU and other CPU, each flat out and paced.
    pub floor: Vec<FloorPoint>,
    /// runtime / raw per hop (per size and wake mode, and per chain), hand-off growth from the
    /// smallest to the largest size, Unix socket / runtime at 1 MiB, each event-woken hop of
    /// the runtime and raw iceoryx2 / the pipe floor.
    pub ratios: Vec<Ratio>,
    /// zenoh over loopback TCP (`mole bench ipc` adds it from mole-bridge's `mole-zenoh-bench`);
    /// `None`: not measured.
    pub zenoh: Option<ZenohReport>,
}

/// zenoh between two processes over loopback TCP: what a stack split by `mole-bridge` pays
/// per message on one machine, next to the shared-memory transports.
#[derive(Debug, Clone, Serialize)]
pub struct ZenohReport {
    /// How it was measured (sessions, processes, QoS), printed as the table's note.
    pub setup: String,
    /// One-way latency (round trip / 2) per payload size.
    pub latency: Vec<ZenohLatencyPoint>,
    /// One publisher flat out at the largest size.
    pub throughput: ZenohThroughput,
}

/// zenoh's one-way latency at one payload size: half of each ping-pong round trip.
#[derive(Debug, Clone, Serialize)]
pub struct ZenohLatencyPoint {
    pub size: usize,
    pub latency: Summary,
}

/// zenoh's throughput: one publisher flat out (CongestionControl::Block: it waits rather than
/// drops, so every message sent arrives).
#[derive(Debug, Clone, Serialize)]
pub struct ZenohThroughput {
    pub size: usize,
    pub sent: u64,
    pub received: u64,
    /// Messages sent per second of sending.
    pub sent_per_s: f64,
    /// Messages received per second, first to last receipt.
    pub received_per_s: f64,
    /// Received megabytes (10⁶ B) per second.
    pub megabytes_per_s: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_and_quick_configs_are_valid() {
        IpcBenchConfig::default().validate().expect("default");
        let quick = IpcBenchConfig::quick();
        quick.validate().expect("quick");
        assert_eq!(quick.sizes, vec![64, 1 << 20]);
        assert_eq!(quick.samples_for(64), 50);
        assert_eq!(quick.samples_for(1 << 20), 20);
    }

    #[test]
    fn bad_configs_are_refused_with_a_reason() {
        let mut c = IpcBenchConfig::quick();
        c.sizes = vec![64, 100];
        assert!(matches!(
            c.validate(),
            Err(BenchError::UnsupportedSize(100))
        ));
        let mut c = IpcBenchConfig::quick();
        c.fanout = vec![9];
        assert!(matches!(c.validate(), Err(BenchError::Config(_))));
        let mut c = IpcBenchConfig::quick();
        c.namespace = "a/b".into();
        assert!(c.validate().is_err());
        let mut c = IpcBenchConfig::quick();
        c.throughput_secs = f64::NAN;
        assert!(c.validate().is_err());
        let mut c = IpcBenchConfig::quick();
        c.sizes.clear();
        assert!(c.validate().is_err());
        let mut c = IpcBenchConfig::quick();
        c.floor_paced_samples = 0;
        assert!(c.validate().is_err());
        let mut c = IpcBenchConfig::quick();
        c.floor_rate_hz = 0.0;
        assert!(c.validate().is_err());
    }
}
