//! `mole bench peers`: one four-process loop built three ways and measured in one run.
//!
//! A source sends a payload every 10 ms (paced) or as soon as the previous one came back (flat
//! out); two stages forward it; a sink forwards it back to the source, which measures the loop.
//! The three builds:
//! - raw iceoryx2 and mole's runtime: the driver (this process) is the source, three
//!   `mole-bench-probe` processes forward ([`crate::driver::Driver::peer_loop`]);
//! - dora-rs: `dora run` (PyPI's `dora-rs-cli`) runs a dataflow of four `mole-dora-peer` nodes
//!   (`processes/bench/peers/dora`, on crates.io's `dora-node-api`), whose source reports to
//!   this process over a Unix socket. Both come from `scripts/dora-env.sh`; without them the
//!   dora rows are skipped with the reason.
//!
//! Every build is measured the same way: loop latency from the source's clock (every sample,
//! nothing filtered), loops per second over the measured loops, and CPU per loop: the run time
//! of every thread of every process below this one (the source, the stages, and dora's daemon)
//! from the kernel's scheduler statistics, read when the warm-up is over and when the last loop
//! is back.

use crate::driver::with_driver;
use crate::{BenchError, IpcBenchConfig, Ratio, Summary, Transport};
use serde::Serialize;
use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The dora-rs version the setup script installs (CLI and node API must match).
pub const DORA_VERSION: &str = "1.1.0";
/// The dora node binary, built by `scripts/dora-env.sh` into `<dora dir>/bin`.
pub const DORA_NODE: &str = "mole-dora-peer";

/// One build of the loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Peer {
    /// iceoryx2 publish-subscribe plus its events, without mole's runtime.
    RawIceoryx2,
    /// mole's runtime: the code path every process of the stack uses.
    Mole,
    /// dora-rs: its daemon and node API.
    Dora,
}

impl Peer {
    /// The name in tables.
    pub fn as_str(self) -> &'static str {
        match self {
            Peer::RawIceoryx2 => "raw iceoryx2",
            Peer::Mole => "mole runtime",
            Peer::Dora => "dora-rs",
        }
    }
}

/// What `mole bench peers` measures.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PeerBenchConfig {
    /// Base of the probe groups' namespaces.
    pub namespace: String,
    /// Payload sizes (bytes); each must have a benchmark message type.
    pub sizes: Vec<usize>,
    /// Loops measured flat out, per build and size.
    pub loops: usize,
    /// Loops measured when paced, per build and size.
    pub paced_loops: usize,
    /// The paced source's rate (Hz).
    pub rate_hz: f64,
    /// Loops before the measured ones (flat out; a tenth of them paced, at least 3).
    pub warm: usize,
    /// How long one loop may take before the run fails (ms).
    pub timeout_ms: u64,
    /// The probe binary; found next to the current executable when `None`.
    pub probe: Option<PathBuf>,
    /// Where `scripts/dora-env.sh` installed dora: `bin/dora` and `bin/mole-dora-peer`.
    pub dora_dir: PathBuf,
    /// Fail instead of skipping when dora is not installed (CI).
    pub require_dora: bool,
}

impl Default for PeerBenchConfig {
    fn default() -> Self {
        PeerBenchConfig {
            namespace: format!("peers{}", std::process::id()),
            sizes: vec![64, 4096],
            loops: 5000,
            paced_loops: 500,
            rate_hz: 100.0,
            warm: 200,
            timeout_ms: 5000,
            probe: None,
            dora_dir: PathBuf::from("target/dora-env"),
            require_dora: false,
        }
    }
}

impl PeerBenchConfig {
    /// A short run for tests: both sizes, 200 loops flat out, 20 paced.
    pub fn quick() -> Self {
        PeerBenchConfig {
            loops: 200,
            paced_loops: 20,
            warm: 20,
            ..PeerBenchConfig::default()
        }
    }

    /// Refuses what cannot run, before any process starts.
    pub fn validate(&self) -> Result<(), BenchError> {
        if let Some(&bad) = self
            .sizes
            .iter()
            .find(|s| !crate::messages::is_supported(**s))
        {
            return Err(BenchError::UnsupportedSize(bad));
        }
        let fail = |why: &str| Err(BenchError::Config(why.to_string()));
        if self.sizes.is_empty() {
            return fail("no payload size selected");
        }
        if self.loops == 0 || self.paced_loops == 0 {
            return fail("--loops and --paced-loops must be at least 1");
        }
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0 && self.rate_hz <= 1000.0) {
            return fail("the paced rate must be in (0, 1000] Hz");
        }
        Ok(())
    }

    fn period(&self) -> Duration {
        Duration::from_secs_f64(1.0 / self.rate_hz)
    }

    fn warm_for(&self, paced: bool) -> usize {
        if paced {
            (self.warm / 10).max(3)
        } else {
            self.warm
        }
    }
}

/// One build, payload size and pacing.
#[derive(Debug, Clone, Serialize)]
pub struct PeerPoint {
    pub peer: Peer,
    pub size: usize,
    /// `None`: flat out.
    pub rate_hz: Option<f64>,
    /// Loop latency, source to source.
    pub latency: Summary,
    /// Measured loops over the time they took.
    pub loops_per_s: f64,
    /// CPU time of every process of the loop (and dora's daemon) per loop (µs).
    pub cpu_us_per_loop: f64,
    /// The same over the wall time: the share of one core the loop kept busy.
    pub cpu_share: f64,
}

/// A build that was not measured, and why.
#[derive(Debug, Clone, Serialize)]
pub struct Skipped {
    pub peer: Peer,
    pub reason: String,
}

/// Everything one run measured.
#[derive(Debug, Clone, Serialize)]
pub struct PeerReport {
    pub config: PeerBenchConfig,
    pub cpus: usize,
    pub points: Vec<PeerPoint>,
    pub skipped: Vec<Skipped>,
    /// mole's p50 and CPU per loop over raw iceoryx2's and dora's, per size and pacing.
    pub ratios: Vec<Ratio>,
}

impl PeerReport {
    /// The point of `peer` at `size`, paced or flat out.
    pub fn point(&self, peer: Peer, size: usize, paced: bool) -> Option<&PeerPoint> {
        self.points
            .iter()
            .find(|p| p.peer == peer && p.size == size && p.rate_hz.is_some() == paced)
    }
}

/// Run time (ns) of every thread of `root` and of every process below it, from
/// `/proc/<pid>/task/<tid>/schedstat` (user and kernel time, in nanoseconds).
pub fn tree_cpu_ns(root: u32) -> u64 {
    let mut parent = HashMap::new();
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return 0;
    };
    for entry in entries.flatten() {
        let Some(pid) = entry
            .file_name()
            .to_str()
            .and_then(|s| s.parse::<u32>().ok())
        else {
            continue;
        };
        if let Some(ppid) = std::fs::read_to_string(entry.path().join("stat"))
            .ok()
            .and_then(|stat| parent_of(&stat))
        {
            parent.insert(pid, ppid);
        }
    }
    let below_root = |mut pid: u32| {
        for _ in 0..64 {
            if pid == root {
                return true;
            }
            match parent.get(&pid) {
                Some(&ppid) if ppid != 0 => pid = ppid,
                _ => return false,
            }
        }
        false
    };
    parent
        .keys()
        .copied()
        .filter(|&pid| below_root(pid))
        .map(process_cpu_ns)
        .sum()
}

/// The parent pid from a `/proc/<pid>/stat` line (after the command name, which may hold
/// spaces and parentheses).
fn parent_of(stat: &str) -> Option<u32> {
    let rest = &stat[stat.rfind(')')? + 1..];
    rest.split_whitespace().nth(1)?.parse().ok()
}

fn process_cpu_ns(pid: u32) -> u64 {
    let Ok(tasks) = std::fs::read_dir(format!("/proc/{pid}/task")) else {
        return 0;
    };
    tasks
        .flatten()
        .filter_map(|t| std::fs::read_to_string(t.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum()
}

/// CPU clocks and wall time around the measured loops.
struct Window {
    cpu_ns: u64,
    wall: Duration,
}

fn measure_window<T>(f: impl FnOnce() -> Result<T, BenchError>) -> Result<(T, Window), BenchError> {
    let me = std::process::id();
    let (cpu0, t0) = (tree_cpu_ns(me), Instant::now());
    let out = f()?;
    let (wall, cpu1) = (t0.elapsed(), tree_cpu_ns(me));
    Ok((
        out,
        Window {
            cpu_ns: cpu1.saturating_sub(cpu0),
            wall,
        },
    ))
}

fn point(
    peer: Peer,
    size: usize,
    rate_hz: Option<f64>,
    mut samples: Vec<u64>,
    window: &Window,
) -> Result<PeerPoint, BenchError> {
    let loops = samples.len();
    let latency = Summary::from_ns(&mut samples)
        .ok_or_else(|| BenchError::Internal(format!("{}: no loop came back", peer.as_str())))?;
    let secs = window.wall.as_secs_f64().max(1e-9);
    Ok(PeerPoint {
        peer,
        size,
        rate_hz,
        latency,
        loops_per_s: loops as f64 / secs,
        cpu_us_per_loop: window.cpu_ns as f64 / 1e3 / loops.max(1) as f64,
        cpu_share: window.cpu_ns as f64 / 1e9 / secs,
    })
}

/// Runs every build of `config` and returns the report; dora is skipped (with the reason) when
/// it is not installed, unless `config.require_dora`.
pub fn run_peer_bench(config: &PeerBenchConfig) -> Result<PeerReport, BenchError> {
    config.validate()?;
    let mut report = PeerReport {
        config: config.clone(),
        cpus: std::thread::available_parallelism().map_or(1, |n| n.get()),
        points: Vec::new(),
        skipped: Vec::new(),
        ratios: Vec::new(),
    };
    let ipc = IpcBenchConfig {
        namespace: config.namespace.clone(),
        timeout_ms: config.timeout_ms,
        probe: config.probe.clone(),
        ..IpcBenchConfig::default()
    };
    let dora = match Dora::find(&config.dora_dir) {
        Ok(dora) => Some(dora),
        Err(reason) if config.require_dora => return Err(BenchError::Config(reason)),
        Err(reason) => {
            report.skipped.push(Skipped {
                peer: Peer::Dora,
                reason,
            });
            None
        }
    };
    for &size in &config.sizes {
        for paced in [false, true] {
            let (loops, period) = if paced {
                (config.paced_loops, Some(config.period()))
            } else {
                (config.loops, None)
            };
            let rate = paced.then_some(config.rate_hz);
            let warm = config.warm_for(paced);
            for (peer, transport) in [
                (Peer::RawIceoryx2, Transport::Raw),
                (Peer::Mole, Transport::Runtime),
            ] {
                let (samples, window) = with_driver(&ipc, |driver| {
                    driver.peer_loop(transport, size, (warm, loops), period, |run| {
                        measure_window(run)
                    })
                })?;
                report
                    .points
                    .push(point(peer, size, rate, samples, &window)?);
            }
            if let Some(dora) = &dora {
                let (samples, window) = dora.run(config, size, (warm, loops), paced)?;
                report
                    .points
                    .push(point(Peer::Dora, size, rate, samples, &window)?);
            }
        }
    }
    report.ratios = ratios(&report);
    Ok(report)
}

fn ratios(report: &PeerReport) -> Vec<Ratio> {
    let mut out = Vec::new();
    for &size in &report.config.sizes {
        for paced in [false, true] {
            let Some(mole) = report.point(Peer::Mole, size, paced) else {
                continue;
            };
            let pacing = if paced {
                format!("{} Hz", report.config.rate_hz)
            } else {
                "flat out".to_string()
            };
            for peer in [Peer::RawIceoryx2, Peer::Dora] {
                if let Some(other) = report.point(peer, size, paced) {
                    out.push(Ratio {
                        what: format!("mole / {} p50, {size} B, {pacing}", peer.as_str()),
                        value: mole.latency.p50_us / other.latency.p50_us.max(1e-9),
                    });
                    out.push(Ratio {
                        what: format!("mole / {} CPU per loop, {size} B, {pacing}", peer.as_str()),
                        value: mole.cpu_us_per_loop / other.cpu_us_per_loop.max(1e-9),
                    });
                }
            }
        }
    }
    out
}

/// `dora run` and the node binary, as `scripts/dora-env.sh` installs them.
struct Dora {
    cli: PathBuf,
    node: PathBuf,
}

/// Kills and reaps `dora run` (and so its nodes) when dropped, whatever happened, then removes
/// the zenoh shared-memory segments that appeared in `/dev/shm` while it ran: dora's data plane
/// is zenoh's shared memory, and `dora run` 1.1 exits without removing its segment (zenoh
/// removes stale ones only when a later process starts).
struct DoraRun {
    child: Child,
    segments_before: Vec<PathBuf>,
}

/// zenoh's shared-memory segments (`/dev/shm/<id>.zenoh`).
fn zenoh_segments() -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir("/dev/shm") else {
        return Vec::new();
    };
    entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "zenoh"))
        .collect()
}

impl DoraRun {
    fn spawn(command: &mut Command) -> Result<DoraRun, BenchError> {
        let segments_before = zenoh_segments();
        let child = command.spawn().map_err(BenchError::Spawn)?;
        Ok(DoraRun {
            child,
            segments_before,
        })
    }
}

impl Drop for DoraRun {
    fn drop(&mut self) {
        self.stop();
        for segment in zenoh_segments() {
            if !self.segments_before.contains(&segment) {
                let _ = std::fs::remove_file(segment);
            }
        }
    }
}

impl DoraRun {
    fn stop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = nix::sys::signal::kill(
                nix::unistd::Pid::from_raw(self.child.id() as i32),
                nix::sys::signal::Signal::SIGINT,
            );
            let deadline = Instant::now() + Duration::from_secs(5);
            while Instant::now() < deadline && matches!(self.child.try_wait(), Ok(None)) {
                std::thread::sleep(Duration::from_millis(10));
            }
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
    }
}

impl Dora {
    fn find(dir: &Path) -> Result<Dora, String> {
        let cli = dir.join("bin/dora");
        let node = dir.join("bin").join(DORA_NODE);
        let setup = "run scripts/dora-env.sh (PyPI's dora-rs-cli and crates.io's dora-node-api)";
        if !cli.is_file() {
            return Err(format!(
                "dora-rs is not installed: no {}; {setup}",
                cli.display()
            ));
        }
        if !node.is_file() {
            return Err(format!(
                "the dora node is not built: no {}; {setup}",
                node.display()
            ));
        }
        let version = Command::new(&cli)
            .arg("--version")
            .output()
            .map_err(|e| format!("{} --version: {e}", cli.display()))?;
        let text = String::from_utf8_lossy(&version.stdout);
        if !text.contains(DORA_VERSION) {
            return Err(format!(
                "{} is `{}`, not {DORA_VERSION} (the node API's version); {setup}",
                cli.display(),
                text.trim()
            ));
        }
        let absolute = |p: PathBuf| std::fs::canonicalize(&p).unwrap_or(p);
        Ok(Dora {
            cli: absolute(cli),
            node: absolute(node),
        })
    }

    /// The dataflow: source → stage1 → stage2 → sink → source.
    fn dataflow(
        &self,
        size: usize,
        (warm, loops): (usize, usize),
        paced: Option<Duration>,
        marks: &Path,
        timeout_ms: u64,
    ) -> String {
        let node = self.node.display();
        // Flat out the timer starts the first loop, then only checks that the loop in flight
        // comes back within the timeout (a stage killed would otherwise hang the run).
        let tick_ms = paced.map_or(50, |p| p.as_millis().max(1));
        let pacing = if paced.is_some() { " --paced" } else { "" };
        let stage = |id: &str, from: &str| {
            format!(
                "  - id: {id}\n    path: {node}\n    args: forward --size {size}\n    inputs:\n      \
                 in: {from}/out\n    outputs:\n      - out\n"
            )
        };
        format!(
            "nodes:\n  - id: source\n    path: {node}\n    args: source --size {size} --warm {warm} \
             --loops {loops}{pacing} --marks {marks} --timeout-ms {timeout_ms}\n    inputs:\n      tick: \
             dora/timer/millis/{tick_ms}\n      back: sink/out\n    outputs:\n      - out\n{}{}{}",
            stage("stage1", "source"),
            stage("stage2", "stage1"),
            stage("sink", "stage2"),
            marks = marks.display(),
        )
    }

    /// One measured run of the loop on dora.
    fn run(
        &self,
        config: &PeerBenchConfig,
        size: usize,
        (warm, loops): (usize, usize),
        paced: bool,
    ) -> Result<(Vec<u64>, Window), BenchError> {
        let io = |what: &'static str| move |source| BenchError::Io { what, source };
        let dir = std::env::temp_dir().join(format!(
            "mole-{}-dora-{size}-{}",
            config.namespace,
            if paced { "paced" } else { "flat" }
        ));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).map_err(io("dora's run directory"))?;
        let _cleanup = RemoveDirOnDrop(dir.clone());
        let marks = dir.join("marks.sock");
        let listener = UnixListener::bind(&marks).map_err(io("bind the marks socket"))?;
        listener.set_nonblocking(true).map_err(io("marks socket"))?;
        let flow = dir.join("dataflow.yml");
        let period = paced.then(|| config.period());
        std::fs::write(
            &flow,
            self.dataflow(size, (warm, loops), period, &marks, config.timeout_ms),
        )
        .map_err(io("write the dataflow"))?;
        let log_path = dir.join("dora.log");
        let log = std::fs::File::create(&log_path).map_err(io("dora's log"))?;
        let mut run = DoraRun::spawn(
            Command::new(&self.cli)
                .arg("run")
                .arg(&flow)
                .current_dir(&dir)
                .stdin(Stdio::null())
                .stdout(log.try_clone().map_err(io("dora's log"))?)
                .stderr(log),
        )?;
        let failed = |run: &mut DoraRun, why: String| {
            let status = run.child.try_wait().ok().flatten();
            let tail = std::fs::read_to_string(&log_path).unwrap_or_default();
            let tail: Vec<&str> = tail.lines().rev().take(8).collect();
            let tail: Vec<&str> = tail.into_iter().rev().collect();
            BenchError::Probe(format!(
                "dora: {why}{}; its log ends:\n{}",
                status
                    .map(|s| format!(" (dora run {s})"))
                    .unwrap_or_default(),
                tail.join("\n")
            ))
        };
        let startup = Instant::now() + Duration::from_secs(60);
        let stream = loop {
            match listener.accept() {
                Ok((stream, _)) => break stream,
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                    if matches!(run.child.try_wait(), Ok(Some(_))) {
                        return Err(failed(
                            &mut run,
                            "the dataflow ended before its source connected".into(),
                        ));
                    }
                    if Instant::now() >= startup {
                        return Err(failed(
                            &mut run,
                            "the source did not connect within 60 s".into(),
                        ));
                    }
                    std::thread::sleep(Duration::from_millis(5));
                }
                Err(e) => return Err(io("accept the source")(e)),
            }
        };
        stream.set_nonblocking(false).map_err(io("marks socket"))?;
        let per_loop = Duration::from_millis(config.timeout_ms) + config.period();
        let budget = per_loop * (warm + loops).min(1000) as u32 + Duration::from_secs(30);
        stream
            .set_read_timeout(Some(budget))
            .map_err(io("marks socket"))?;
        let mut replies = stream.try_clone().map_err(io("marks socket"))?;
        let mut lines = BufReader::new(stream);
        let mut line = String::new();
        let next = |lines: &mut BufReader<_>, line: &mut String| -> Result<(), String> {
            line.clear();
            match lines.read_line(line) {
                Ok(0) => Err("the source closed its socket".to_string()),
                Ok(_) => Ok(()),
                Err(e) => Err(format!("reading the source: {e}")),
            }
        };
        next(&mut lines, &mut line).map_err(|why| failed(&mut run, why))?;
        if line.trim() != "start" {
            return Err(failed(
                &mut run,
                format!("expected `start`, got `{}`", line.trim()),
            ));
        }
        let me = std::process::id();
        let cpu0 = tree_cpu_ns(me);
        writeln!(replies, "go").map_err(io("marks socket"))?;
        next(&mut lines, &mut line).map_err(|why| failed(&mut run, why))?;
        let cpu1 = tree_cpu_ns(me);
        let mut end = line.split_whitespace();
        let (Some("end"), Some(elapsed), Some(count)) = (end.next(), end.next(), end.next()) else {
            return Err(failed(
                &mut run,
                format!("expected `end`, got `{}`", line.trim()),
            ));
        };
        let elapsed_ns: u64 = elapsed
            .parse()
            .map_err(|_| failed(&mut run, format!("bad end line `{}`", line.trim())))?;
        let count: usize = count
            .parse()
            .map_err(|_| failed(&mut run, format!("bad end line `{}`", line.trim())))?;
        let mut samples = Vec::with_capacity(count);
        for _ in 0..count {
            next(&mut lines, &mut line).map_err(|why| failed(&mut run, why))?;
            samples.push(
                line.trim()
                    .parse::<u64>()
                    .map_err(|_| failed(&mut run, format!("bad sample `{}`", line.trim())))?,
            );
        }
        writeln!(replies, "ok").map_err(io("marks socket"))?;
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            match run.child.try_wait() {
                Ok(Some(status)) if status.success() => break,
                Ok(Some(status)) => {
                    return Err(failed(&mut run, format!("dora run ended with {status}")));
                }
                Ok(None) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(10))
                }
                Ok(None) => {
                    return Err(failed(
                        &mut run,
                        "the dataflow did not end after its source".into(),
                    ));
                }
                Err(e) => return Err(io("wait for dora")(e)),
            }
        }
        if samples.len() != loops {
            return Err(failed(
                &mut run,
                format!("{} loops measured, {loops} asked for", samples.len()),
            ));
        }
        Ok((
            samples,
            Window {
                cpu_ns: cpu1.saturating_sub(cpu0),
                wall: Duration::from_nanos(elapsed_ns),
            },
        ))
    }
}

/// Removes a directory when dropped.
struct RemoveDirOnDrop(PathBuf);

impl Drop for RemoveDirOnDrop {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The report as a Markdown table: one row per build, size and pacing, with mole's ratios.
pub fn format_peer_table(report: &PeerReport) -> String {
    let mut out = String::from(
        "| loop | payload | pacing | p50 µs | p99 µs | max µs | loops/s | CPU µs/loop | CPU share |\n\
         | --- | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: |\n",
    );
    for p in &report.points {
        let pacing = p
            .rate_hz
            .map_or("flat out".to_string(), |hz| format!("{hz} Hz"));
        out.push_str(&format!(
            "| {} | {} B | {pacing} | {:.0} | {:.0} | {:.0} | {:.0} | {:.1} | {:.1}% |\n",
            p.peer.as_str(),
            p.size,
            p.latency.p50_us,
            p.latency.p99_us,
            p.latency.max_us,
            p.loops_per_s,
            p.cpu_us_per_loop,
            100.0 * p.cpu_share,
        ));
    }
    for r in &report.ratios {
        out.push_str(&format!("\n{}: {:.2}", r.what, r.value));
    }
    for s in &report.skipped {
        out.push_str(&format!("\n{}: SKIPPED: {}", s.peer.as_str(), s.reason));
    }
    out.push('\n');
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_parent_is_read_after_a_command_name_with_spaces_and_parentheses() {
        assert_eq!(parent_of("42 (a (b) c) S 7 42 42 0 -1"), Some(7));
        assert_eq!(parent_of("42 no parenthesis"), None);
    }

    #[test]
    fn this_process_tree_counts_at_least_this_threads_own_cpu_time() {
        use nix::time::{ClockId, clock_gettime};
        let thread_ns = || {
            let t = clock_gettime(ClockId::CLOCK_THREAD_CPUTIME_ID).expect("thread clock");
            t.tv_sec() as u64 * 1_000_000_000 + t.tv_nsec() as u64
        };
        let me = std::process::id();
        let (tree0, thread0) = (tree_cpu_ns(me), thread_ns());
        let mut x = 0u64;
        while thread_ns() < thread0 + 20_000_000 {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1);
        }
        std::hint::black_box(x);
        let (thread1, tree1) = (thread_ns(), tree_cpu_ns(me));
        assert!(
            tree1 - tree0 >= thread1 - thread0,
            "the tree ran {} ns while this thread alone ran {} ns",
            tree1 - tree0,
            thread1 - thread0
        );
    }

    #[test]
    fn the_dataflow_closes_the_loop_back_to_the_source() {
        let dora = Dora {
            cli: "dora".into(),
            node: "/bin/peer".into(),
        };
        let flat = dora.dataflow(64, (10, 100), None, Path::new("/tmp/m.sock"), 5000);
        assert!(flat.contains("back: sink/out"), "{flat}");
        assert!(flat.contains("in: source/out") && flat.contains("in: stage1/out"));
        assert!(flat.contains("in: stage2/out"));
        assert!(!flat.contains("--paced"));
        let paced = dora.dataflow(
            4096,
            (3, 20),
            Some(Duration::from_millis(10)),
            Path::new("/m"),
            250,
        );
        assert!(paced.contains("dora/timer/millis/10") && paced.contains("--paced"));
        assert!(paced.contains("--timeout-ms 250"));
        assert!(paced.contains("--size 4096 --warm 3 --loops 20"));
    }

    #[test]
    fn a_missing_dora_is_a_reason_not_a_failure() {
        let why = Dora::find(Path::new("/nonexistent"))
            .err()
            .expect("not installed");
        assert!(why.contains("scripts/dora-env.sh"), "{why}");
        let config = PeerBenchConfig {
            sizes: vec![100],
            ..PeerBenchConfig::quick()
        };
        assert!(matches!(
            config.validate(),
            Err(BenchError::UnsupportedSize(100))
        ));
    }
}
