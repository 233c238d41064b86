//! The driver: starts the probe groups, runs every measurement, and cleans up after them.

use crate::floor::{Pinning, PipePair, Placement};
use crate::link::{self, Link, STOP, StreamLink};
use crate::messages::with_message_type;
use crate::probe::{CHAIN_HOPS, LOOP_STAGES, driver_ports};
use crate::roles;
use crate::{
    BenchError, ChainPoint, FanoutPoint, FloorPoint, IpcBenchConfig, IpcReport, LatencyPoint,
    PROBE_BINARY, ProbeArgs, ProbeKind, Ratio, Summary, ThroughputPoint, Transport, WakeMode,
};
use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use std::cell::Cell;
use std::fs::File;
use std::os::fd::OwnedFd;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};
use std::time::{Duration, Instant};

/// How long the probes of a group get to come up and answer the hand-shake.
const STARTUP: Duration = Duration::from_secs(20);
/// How long probes get to exit on their own after the stop message.
const GRACE: Duration = Duration::from_secs(5);

/// Where the probe binary is: `config.probe`, else next to the current executable, else one
/// directory up (tests and examples run from `target/<profile>/{deps,examples}`), else `PATH`.
pub fn find_probe(config: &IpcBenchConfig) -> Result<PathBuf, BenchError> {
    if let Some(path) = &config.probe {
        return if path.is_file() {
            Ok(path.clone())
        } else {
            Err(BenchError::ProbeNotFound(path.display().to_string()))
        };
    }
    let mut candidates = Vec::new();
    if let Ok(exe) = std::env::current_exe()
        && let Some(dir) = exe.parent()
    {
        candidates.push(dir.join(PROBE_BINARY));
        if let Some(up) = dir.parent() {
            candidates.push(up.join(PROBE_BINARY));
        }
    }
    if let Some(path) = std::env::var_os("PATH") {
        candidates.extend(std::env::split_paths(&path).map(|d| d.join(PROBE_BINARY)));
    }
    candidates
        .iter()
        .find(|p| p.is_file())
        .cloned()
        .ok_or_else(|| {
            let tried: Vec<String> = candidates
                .iter()
                .take(3)
                .map(|p| p.display().to_string())
                .collect();
            BenchError::ProbeNotFound(format!("{}, and PATH", tried.join(", ")))
        })
}

/// Names of the nodes (alive or dead) left in any probe group of `namespace`: empty after a
/// clean run.
pub fn live_bench_nodes(namespace: &str) -> Vec<String> {
    let prefix = format!("mole/{namespace}-");
    let mut names = Vec::new();
    let _ = Node::<ipc::Service>::list(Config::global_config(), |state| {
        let details = match &state {
            NodeState::Alive(view) => view.details().clone(),
            NodeState::Dead(view) => view.details().clone(),
            _ => None,
        };
        if let Some(details) = details {
            let name = details.name().to_string();
            if name.starts_with(&prefix) {
                names.push(name);
            }
        }
        CallbackProgression::Continue
    });
    names
}

/// A group of probe processes: killed and reaped when dropped, whatever happened.
struct Probes {
    children: Vec<Child>,
}

impl Probes {
    fn spawn(exe: &Path, group: &[ProbeArgs]) -> Result<Probes, BenchError> {
        let mut probes = Probes {
            children: Vec::with_capacity(group.len()),
        };
        for args in group {
            let child = Command::new(exe)
                .args(args.to_args())
                .stdin(Stdio::null())
                .stdout(Stdio::null())
                .stderr(Stdio::inherit())
                .spawn()
                .map_err(BenchError::Spawn)?;
            probes.children.push(child);
        }
        Ok(probes)
    }

    /// One probe whose standard input and output are pipes from and to the driver.
    fn spawn_piped(
        exe: &Path,
        args: &ProbeArgs,
    ) -> Result<(Probes, ChildStdin, ChildStdout), BenchError> {
        let mut child = Command::new(exe)
            .args(args.to_args())
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(BenchError::Spawn)?;
        let pipes = child.stdin.take().zip(child.stdout.take());
        let probes = Probes {
            children: vec![child],
        };
        let (stdin, stdout) =
            pipes.ok_or_else(|| BenchError::Internal("the probe has no pipes".to_string()))?;
        Ok((probes, stdin, stdout))
    }

    /// Why a probe already exited, if one did.
    fn exited(&mut self) -> Option<String> {
        self.children.iter_mut().find_map(|c| match c.try_wait() {
            Ok(Some(status)) => Some(format!("a probe exited early ({status})")),
            _ => None,
        })
    }

    /// Waits for every probe to exit on its own; kills whatever is left after `grace`.
    fn finish(mut self, grace: Duration) -> Result<(), BenchError> {
        let deadline = Instant::now() + grace;
        let mut failures = Vec::new();
        for child in &mut self.children {
            loop {
                match child.try_wait() {
                    Ok(Some(status)) => {
                        if !status.success() {
                            failures.push(format!("probe {} {status}", child.id()));
                        }
                        break;
                    }
                    Ok(None) if Instant::now() < deadline => {
                        std::thread::sleep(Duration::from_millis(2));
                    }
                    Ok(None) => {
                        let _ = child.kill();
                        let _ = child.wait();
                        failures.push(format!("probe {} did not stop", child.id()));
                        break;
                    }
                    Err(e) => {
                        failures.push(format!("probe {}: {e}", child.id()));
                        break;
                    }
                }
            }
        }
        self.children.clear();
        if failures.is_empty() {
            Ok(())
        } else {
            Err(BenchError::Probe(failures.join("; ")))
        }
    }
}

impl Drop for Probes {
    fn drop(&mut self) {
        for child in &mut self.children {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// Removes a socket file when dropped.
struct RemoveOnDrop(PathBuf);

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Accepts the probe's connection, failing if the probe died or took too long.
fn accept<S>(
    mut try_accept: impl FnMut() -> std::io::Result<S>,
    probes: &mut Probes,
) -> Result<S, BenchError> {
    let deadline = Instant::now() + STARTUP;
    loop {
        match try_accept() {
            Ok(stream) => return Ok(stream),
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                if let Some(why) = probes.exited() {
                    return Err(BenchError::Startup(why));
                }
                if Instant::now() >= deadline {
                    return Err(BenchError::Startup(
                        "the probe did not connect its socket".to_string(),
                    ));
                }
                std::thread::sleep(Duration::from_millis(1));
            }
            Err(source) => {
                return Err(BenchError::Io {
                    what: "accept",
                    source,
                });
            }
        }
    }
}

fn io(what: &'static str) -> impl Fn(std::io::Error) -> BenchError {
    move |source| BenchError::Io { what, source }
}

fn summarize(samples: &mut [u64]) -> Result<Summary, BenchError> {
    Summary::from_ns(samples).ok_or_else(|| BenchError::Internal("no samples".to_string()))
}

pub(crate) struct Driver<'c> {
    config: &'c IpcBenchConfig,
    probe: PathBuf,
    groups: Cell<usize>,
    timeout: Duration,
}

impl Driver<'_> {
    /// A fresh namespace for the next probe group.
    fn namespace(&self) -> String {
        let n = self.groups.get();
        self.groups.set(n + 1);
        format!("{}-{n}", self.config.namespace)
    }

    /// Runs `drive` on the driver's endpoint of `transport` while `probes` probes run.
    fn group<T>(
        &self,
        transport: Transport,
        kind: ProbeKind,
        size: usize,
        wake: WakeMode,
        probes: usize,
        drive: impl FnOnce(&mut dyn Link) -> Result<T, BenchError>,
    ) -> Result<T, BenchError> {
        let namespace = self.namespace();
        let args = |id: usize, address: Option<String>| ProbeArgs {
            namespace: namespace.clone(),
            transport,
            kind,
            size,
            wake,
            id: id as u32,
            address,
            idle_ms: (self.timeout * 4).as_millis() as u64,
        };
        match transport {
            Transport::Runtime | Transport::Raw => {
                let ports = driver_ports(kind);
                let group: Vec<ProbeArgs> = (0..probes).map(|id| args(id, None)).collect();
                let run = |link: &mut dyn Link| {
                    let started = Probes::spawn(&self.probe, &group)?;
                    let result = drive(link)?;
                    started.finish(GRACE)?;
                    Ok(result)
                };
                with_message_type!(size, M => if transport == Transport::Runtime {
                    link::with_runtime::<M, T>(&namespace, "driver", &ports, wake, run)
                } else {
                    link::with_raw::<M, T>(&namespace, "driver", &ports, wake, run)
                })
            }
            Transport::Unix => {
                let path = std::env::temp_dir().join(format!("mole-{namespace}.sock"));
                let _ = std::fs::remove_file(&path);
                let listener = std::os::unix::net::UnixListener::bind(&path).map_err(io("bind"))?;
                let _remove = RemoveOnDrop(path.clone());
                listener.set_nonblocking(true).map_err(io("listen"))?;
                let address = path.display().to_string();
                let mut started = Probes::spawn(&self.probe, &[args(0, Some(address))])?;
                let stream = accept(|| listener.accept().map(|(s, _)| s), &mut started)?;
                stream.set_nonblocking(false).map_err(io("socket"))?;
                stream
                    .set_read_timeout(Some(self.timeout))
                    .map_err(io("socket"))?;
                let mut link = StreamLink::new(stream, size);
                let result = drive(&mut link)?;
                drop(link);
                started.finish(GRACE)?;
                Ok(result)
            }
            Transport::Tcp => {
                let listener = std::net::TcpListener::bind("127.0.0.1:0").map_err(io("bind"))?;
                let port = listener.local_addr().map_err(io("bind"))?.port();
                listener.set_nonblocking(true).map_err(io("listen"))?;
                let address = format!("127.0.0.1:{port}");
                let mut started = Probes::spawn(&self.probe, &[args(0, Some(address))])?;
                let stream = accept(|| listener.accept().map(|(s, _)| s), &mut started)?;
                stream.set_nonblocking(false).map_err(io("socket"))?;
                stream.set_nodelay(true).map_err(io("TCP_NODELAY"))?;
                stream
                    .set_read_timeout(Some(self.timeout))
                    .map_err(io("socket"))?;
                let mut link = StreamLink::new(stream, size);
                let result = drive(&mut link)?;
                drop(link);
                started.finish(GRACE)?;
                Ok(result)
            }
            Transport::Pipe => {
                let (started, stdin, stdout) = Probes::spawn_piped(&self.probe, &args(0, None))?;
                let pipes = PipePair::new(
                    File::from(OwnedFd::from(stdout)),
                    File::from(OwnedFd::from(stdin)),
                    Some(self.timeout),
                );
                let mut link = StreamLink::new(pipes, size);
                let result = drive(&mut link)?;
                drop(link);
                started.finish(GRACE)?;
                Ok(result)
            }
        }
    }

    fn latency(
        &self,
        transport: Transport,
        wake: WakeMode,
        size: usize,
    ) -> Result<LatencyPoint, BenchError> {
        let samples = self.config.samples_for(size);
        let warm = (samples / 10).clamp(1, 100);
        let timeout = self.timeout;
        let mut s = self.group(transport, ProbeKind::Latency, size, wake, 1, |link| {
            roles::handshake(link, 1, Instant::now() + STARTUP)?;
            roles::drive_latency(link, 1, warm, samples, None, timeout)
        })?;
        Ok(LatencyPoint {
            transport,
            wake,
            size,
            latency: summarize(&mut s.latency)?,
            handoff: summarize(&mut s.handoff)?,
            fill: summarize(&mut s.fill)?,
        })
    }

    fn throughput(&self, transport: Transport, size: usize) -> Result<ThroughputPoint, BenchError> {
        let wake = if transport.is_ipc() {
            WakeMode::Busy
        } else {
            WakeMode::Blocking
        };
        let duration = Duration::from_secs_f64(self.config.throughput_secs);
        let timeout = self.timeout;
        let t = self.group(transport, ProbeKind::Throughput, size, wake, 1, |link| {
            roles::handshake(link, 1, Instant::now() + STARTUP)?;
            roles::drive_throughput(link, duration, timeout)
        })?;
        let received = t.totals.count;
        let window = t.totals.recv_ns.saturating_sub(t.totals.first_ns) as f64 / 1e9;
        let received_per_s = if received >= 2 && window > 0.0 {
            (received - 1) as f64 / window
        } else {
            received as f64 / t.send_secs.max(1e-9)
        };
        Ok(ThroughputPoint {
            transport,
            size,
            sent: t.sent,
            received,
            sent_per_s: t.sent as f64 / t.send_secs.max(1e-9),
            received_per_s,
            bytes_per_s: received_per_s * size as f64,
        })
    }

    fn fanout(&self, transport: Transport, subscribers: usize) -> Result<FanoutPoint, BenchError> {
        let size = self.config.fanout_size;
        let samples = self.config.fanout_samples;
        let warm = (samples / 10).clamp(1, 100);
        let timeout = self.timeout;
        let kind = ProbeKind::Fanout;
        let mut s = self.group(
            transport,
            kind,
            size,
            WakeMode::Event,
            subscribers,
            |link| {
                roles::handshake(link, subscribers, Instant::now() + STARTUP)?;
                roles::drive_latency(link, subscribers, warm, samples, None, timeout)
            },
        )?;
        Ok(FanoutPoint {
            transport,
            subscribers,
            size,
            latency: summarize(&mut s.latency)?,
        })
    }

    fn chain(&self, transport: Transport) -> Result<[ChainPoint; 2], BenchError> {
        let (flat_n, paced_n) = (self.config.chain_samples, self.config.chain_paced_samples);
        let period = Duration::from_secs_f64(1.0 / self.config.chain_rate_hz);
        let timeout = self.timeout;
        let size = self.config.fanout_size;
        let kind = ProbeKind::Chain;
        let (mut flat, mut paced) =
            self.group(transport, kind, size, WakeMode::Event, CHAIN_HOPS, |link| {
                roles::chain_handshake(link, Instant::now() + STARTUP)?;
                let warm = (flat_n / 10).clamp(1, 100);
                let flat = roles::drive_chain(link, 0, warm, flat_n, None, timeout)?;
                let paced = roles::drive_chain(link, 1 << 40, 3, paced_n, Some(period), timeout)?;
                link.send(STOP, None, false)?;
                Ok((flat, paced))
            })?;
        Ok([
            ChainPoint {
                transport,
                hops: CHAIN_HOPS,
                rate_hz: None,
                latency: summarize(&mut flat)?,
            },
            ChainPoint {
                transport,
                hops: CHAIN_HOPS,
                rate_hz: Some(self.config.chain_rate_hz),
                latency: summarize(&mut paced)?,
            },
        ])
    }

    /// The pipe wake-up floor for `placement` at `rate_hz` (None: flat out). The driver's
    /// thread is pinned to the probe's CPU while the probe is spawned (it inherits the mask),
    /// then to its own; refused pinning runs both unpinned and says why.
    fn floor(&self, placement: Placement, rate_hz: Option<f64>) -> Result<FloorPoint, BenchError> {
        let (samples, warm) = match rate_hz {
            None => (self.config.floor_samples, 100),
            Some(_) => (self.config.floor_paced_samples, 3),
        };
        let warm = warm.min(samples.div_ceil(10));
        let period = rate_hz.map(|hz| Duration::from_secs_f64(1.0 / hz));
        let timeout = self.timeout + period.unwrap_or_default();
        let mut pinning = Pinning::for_spawn(placement);
        let kind = ProbeKind::Latency;
        let size = self.config.fanout_size;
        let mut s = self.group(Transport::Pipe, kind, size, WakeMode::Blocking, 1, |link| {
            pinning.move_to_waker();
            roles::handshake(link, 1, Instant::now() + STARTUP)?;
            roles::drive_latency(link, 1, warm, samples, period, timeout)
        })?;
        Ok(FloorPoint {
            transport: Transport::Pipe,
            placement,
            rate_hz,
            cpus: pinning.cpus,
            unpinned: pinning.unpinned.take(),
            latency: summarize(&mut s.latency)?,
        })
    }

    /// `mole bench peers`' loop on `transport`: the driver is the source, [`LOOP_STAGES`] probes
    /// forward (the last closes the loop). After `warm` loops, `measure` is called around the
    /// measured ones (it reads the CPU clocks), which it gets as origin → back latencies.
    pub(crate) fn peer_loop<T>(
        &self,
        transport: Transport,
        size: usize,
        (warm, loops): (usize, usize),
        period: Option<Duration>,
        measure: impl FnOnce(&mut dyn FnMut() -> Result<Vec<u64>, BenchError>) -> Result<T, BenchError>,
    ) -> Result<T, BenchError> {
        let timeout = self.timeout + period.unwrap_or_default();
        let kind = ProbeKind::Loop;
        self.group(
            transport,
            kind,
            size,
            WakeMode::Event,
            LOOP_STAGES,
            |link| {
                roles::chain_handshake(link, Instant::now() + STARTUP)?;
                roles::drive_chain(link, 0, warm, 0, period, timeout)?;
                let first = warm as u64;
                let result =
                    measure(&mut || roles::drive_chain(link, first, 0, loops, period, timeout))?;
                link.send(STOP, None, false)?;
                Ok(result)
            },
        )
    }

    fn run(&self) -> Result<IpcReport, BenchError> {
        let c = self.config;
        let mut report = IpcReport {
            config: c.clone(),
            cpus: std::thread::available_parallelism().map_or(1, |n| n.get()),
            latency: Vec::new(),
            throughput: Vec::new(),
            fanout: Vec::new(),
            chain: Vec::new(),
            floor: Vec::new(),
            ratios: Vec::new(),
            zenoh: None,
        };
        for placement in [Placement::Same, Placement::Other] {
            for rate_hz in [None, Some(c.floor_rate_hz)] {
                report.floor.push(self.floor(placement, rate_hz)?);
            }
        }
        for &size in &c.sizes {
            for transport in [Transport::Runtime, Transport::Raw] {
                for wake in [WakeMode::Busy, WakeMode::Event] {
                    report.latency.push(self.latency(transport, wake, size)?);
                }
            }
            for transport in [Transport::Unix, Transport::Tcp] {
                report
                    .latency
                    .push(self.latency(transport, WakeMode::Blocking, size)?);
            }
        }
        for &size in &c.sizes {
            for transport in [
                Transport::Runtime,
                Transport::Raw,
                Transport::Unix,
                Transport::Tcp,
            ] {
                report.throughput.push(self.throughput(transport, size)?);
            }
        }
        for &n in &c.fanout {
            for transport in [Transport::Runtime, Transport::Raw] {
                report.fanout.push(self.fanout(transport, n)?);
            }
        }
        for transport in [Transport::Runtime, Transport::Raw] {
            report.chain.extend(self.chain(transport)?);
        }
        report.ratios = ratios(&report);
        Ok(report)
    }
}

/// Runs every measurement of `config` and returns the report. Checks the configuration first
/// (an unsupported size is [`BenchError::UnsupportedSize`]); every probe is stopped and reaped
/// and dead nodes are cleaned, whatever the outcome.
pub fn run_ipc_bench(config: &IpcBenchConfig) -> Result<IpcReport, BenchError> {
    config.validate()?;
    with_driver(config, |driver| driver.run())
}

/// Runs `f` on a driver for `config`'s probes, then cleans dead nodes whatever the outcome.
pub(crate) fn with_driver<T>(
    config: &IpcBenchConfig,
    f: impl FnOnce(&Driver<'_>) -> Result<T, BenchError>,
) -> Result<T, BenchError> {
    let probe = find_probe(config)?;
    let driver = Driver {
        config,
        probe,
        groups: Cell::new(0),
        timeout: Duration::from_millis(config.timeout_ms),
    };
    let result = f(&driver);
    mole_runtime::cleanup_dead_nodes();
    result
}

fn p50(points: &[LatencyPoint], t: Transport, w: WakeMode, size: usize) -> Option<f64> {
    points
        .iter()
        .find(|p| p.transport == t && p.wake == w && p.size == size)
        .map(|p| p.latency.p50_us)
}

fn push_ratio(out: &mut Vec<Ratio>, what: String, num: Option<f64>, den: Option<f64>) {
    if let (Some(num), Some(den)) = (num, den)
        && den > 0.0
    {
        out.push(Ratio {
            what,
            value: num / den,
        });
    }
}

/// The ratios the issue asks for, from whatever points the report holds.
pub(crate) fn ratios(report: &IpcReport) -> Vec<Ratio> {
    let mut out = Vec::new();
    let lat = &report.latency;
    let mut sizes: Vec<usize> = lat.iter().map(|p| p.size).collect();
    sizes.sort_unstable();
    sizes.dedup();
    for &size in &sizes {
        for wake in [WakeMode::Busy, WakeMode::Event] {
            push_ratio(
                &mut out,
                format!(
                    "runtime / raw p50 per hop, {}, {}",
                    wake.as_str(),
                    crate::report::size_label(size)
                ),
                p50(lat, Transport::Runtime, wake, size),
                p50(lat, Transport::Raw, wake, size),
            );
        }
    }
    for rate in [None, Some(report.config.chain_rate_hz)] {
        let chain = |t: Transport| {
            report
                .chain
                .iter()
                .find(|c| c.transport == t && c.rate_hz == rate)
                .map(|c| c.latency.p50_us)
        };
        let pacing = rate.map_or("flat out".to_string(), |hz| format!("{hz} Hz"));
        push_ratio(
            &mut out,
            format!("runtime / raw p50, five-hop chain {pacing}"),
            chain(Transport::Runtime),
            chain(Transport::Raw),
        );
    }
    if let (Some(&small), Some(&large)) = (sizes.first(), sizes.last())
        && large > small
    {
        for transport in [Transport::Runtime, Transport::Raw] {
            for wake in [WakeMode::Busy, WakeMode::Event] {
                let handoff = |size: usize| {
                    lat.iter()
                        .find(|p| p.transport == transport && p.wake == wake && p.size == size)
                        .map(|p| p.handoff.p50_us)
                };
                push_ratio(
                    &mut out,
                    format!(
                        "hand-off p50 {} / {}, {} {}",
                        crate::report::size_label(large),
                        crate::report::size_label(small),
                        transport.as_str(),
                        wake.as_str()
                    ),
                    handoff(large),
                    handoff(small),
                );
            }
        }
    }
    for wake in [WakeMode::Busy, WakeMode::Event] {
        push_ratio(
            &mut out,
            format!("unix socket / runtime {} p50, 1 MiB", wake.as_str()),
            p50(lat, Transport::Unix, WakeMode::Blocking, 1 << 20),
            p50(lat, Transport::Runtime, wake, 1 << 20),
        );
    }
    floor_ratios(report, &mut out);
    out
}

/// How far each event-woken hop of the runtime and raw iceoryx2 is from the pipe floor: a
/// ping-pong hop (at the floor's message size) against the floor flat out, a hop of the paced
/// chain (its p50 over its hops) against the paced floor; for each placement of the floor.
fn floor_ratios(report: &IpcReport, out: &mut Vec<Ratio>) {
    let size = report.config.fanout_size;
    for placement in [Placement::Same, Placement::Other] {
        let floor = |paced: bool| {
            report
                .floor
                .iter()
                .find(|f| f.placement == placement && f.rate_hz.is_some() == paced)
                .map(|f| f.latency.p50_us)
        };
        for transport in [Transport::Runtime, Transport::Raw] {
            push_ratio(
                out,
                format!(
                    "{} event hop / pipe floor p50, flat out, {}",
                    transport.as_str(),
                    placement.as_str()
                ),
                p50(&report.latency, transport, WakeMode::Event, size),
                floor(false),
            );
            let chain_hop = report
                .chain
                .iter()
                .find(|c| c.transport == transport && c.rate_hz.is_some())
                .map(|c| c.latency.p50_us / c.hops.max(1) as f64);
            push_ratio(
                out,
                format!(
                    "{} chain hop / pipe floor p50, paced, {}",
                    transport.as_str(),
                    placement.as_str()
                ),
                chain_hop,
                floor(true),
            );
        }
    }
}
