//! `mole top`: a live view of a running stack (topics, processes), refreshed every second.

use crate::Failure;
use crate::stats::StatsCollector;
use clap::Args;
use mole_runtime::{ClockMode, CommonArgs, Context, Subscriber, live_nodes_in_namespace};
use mole_types::graph::nodes;
use mole_types::graph::nodes::TOP;
use mole_types::{
    GRAPH, PROCESS_EXITED, PROCESS_FAILED, PROCESS_RESTARTING, PROCESS_RUNNING, Processes,
    RunStatus, Stats, read_name, topics,
};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::Write as _;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

#[derive(Debug, Args)]
pub struct TopArgs {
    /// Namespace of the stack to watch.
    #[arg(long, default_value = mole_types::env::DEFAULT_NAMESPACE)]
    pub namespace: String,
    /// Print one snapshot (after two seconds of statistics) and exit.
    #[arg(long)]
    pub once: bool,
}

/// Per process: the last two CPU readings, for a CPU percentage.
#[derive(Default)]
struct CpuSample {
    pid: u32,
    last: Option<(Instant, u64)>,
    percent: f64,
    rss_mib: f64,
}

struct Ports {
    stats: Subscriber<Stats>,
    processes: Subscriber<Processes>,
    status: Subscriber<RunStatus>,
}

fn open(namespace: &str, shutdown: Arc<AtomicBool>) -> Result<(Context, Ports), Failure> {
    // The services keep the stack's clock mode (it decides whether they may drop); try both.
    let mut last_error = String::new();
    for mode in [ClockMode::Realtime, ClockMode::Lockstep] {
        let args = CommonArgs::attach(namespace, mode);
        let ctx = Context::with_shutdown_flag(nodes::TOP, &args, shutdown.clone())
            .map_err(|e| Failure::run(e.to_string()))?;
        let ports = (|| {
            Ok::<_, mole_runtime::RuntimeError>(Ports {
                stats: ctx.subscriber(topics::STACK_STATS)?,
                processes: ctx.subscriber(topics::STACK_PROCESSES)?,
                status: ctx.subscriber(topics::MONITOR_STATUS)?,
            })
        })();
        match ports {
            Ok(ports) => return Ok((ctx, ports)),
            Err(e) => last_error = e.to_string(),
        }
    }
    Err(Failure::run(format!(
        "cannot attach to the stack: {last_error}"
    )))
}

/// Restores the terminal on drop.
struct RawTerminal {
    saved: Option<nix::sys::termios::Termios>,
}

impl RawTerminal {
    fn new() -> Self {
        use nix::sys::termios::{LocalFlags, SetArg, tcgetattr, tcsetattr};
        let stdin = std::io::stdin();
        let Ok(saved) = tcgetattr(&stdin) else {
            return Self { saved: None };
        };
        let mut raw = saved.clone();
        raw.local_flags
            .remove(LocalFlags::ICANON | LocalFlags::ECHO);
        let _ = tcsetattr(&stdin, SetArg::TCSANOW, &raw);
        Self { saved: Some(saved) }
    }

    /// Whether `q` was typed since the last call.
    fn quit_requested(&self) -> bool {
        use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
        use std::io::Read;
        use std::os::fd::AsFd;
        if self.saved.is_none() {
            return false;
        }
        let stdin = std::io::stdin();
        let mut fds = [PollFd::new(stdin.as_fd(), PollFlags::POLLIN)];
        if poll(&mut fds, PollTimeout::ZERO).unwrap_or(0) == 0 {
            return false;
        }
        let mut byte = [0u8; 1];
        matches!(stdin.lock().read(&mut byte), Ok(1) if byte[0] == b'q' || byte[0] == b'Q')
    }
}

impl Drop for RawTerminal {
    fn drop(&mut self) {
        if let Some(saved) = &self.saved {
            let _ = nix::sys::termios::tcsetattr(
                std::io::stdin(),
                nix::sys::termios::SetArg::TCSANOW,
                saved,
            );
        }
    }
}

/// The rows of the process table: the graph's roles in its order, then any other process the
/// launcher supervises or that publishes statistics (not the launcher and `mole top` themselves).
fn listed_roles(
    supervised: impl IntoIterator<Item = String>,
    heard: impl IntoIterator<Item = String>,
) -> Vec<String> {
    let mut roles: Vec<String> = GRAPH.iter().map(|r| r.role.name().to_owned()).collect();
    for role in supervised.into_iter().chain(heard) {
        if !roles.contains(&role) && role != nodes::LAUNCHER && role != nodes::TOP {
            roles.push(role);
        }
    }
    roles
}

fn state_name(state: u32) -> &'static str {
    match state {
        PROCESS_RUNNING => "running",
        PROCESS_RESTARTING => "restarting",
        PROCESS_EXITED => "exited",
        PROCESS_FAILED => "failed",
        _ => "starting",
    }
}

/// Watches the stack in `args.namespace` until q, Ctrl-C, or (with --once) one snapshot.
pub fn top(args: &TopArgs) -> Result<(), Failure> {
    let live: Vec<String> = live_nodes_in_namespace(&args.namespace)
        .into_iter()
        .filter(|n| !n.ends_with(&format!("/{TOP}")))
        .collect();
    if live.is_empty() {
        return Err(Failure::input(format!(
            "no stack is running in namespace `{}` (start one with `mole up --namespace {}`)",
            args.namespace, args.namespace
        )));
    }
    let shutdown = Arc::new(AtomicBool::new(false));
    let flag = shutdown.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .map_err(|e| Failure::run(format!("cannot install the Ctrl-C handler: {e}")))?;
    let (_ctx, mut ports) = open(&args.namespace, shutdown.clone())?;
    let terminal = (!args.once).then(RawTerminal::new);

    let started = Instant::now();
    let mut collector = StatsCollector::default();
    let mut latest: BTreeMap<String, Box<Stats>> = BTreeMap::new();
    let mut cpu: BTreeMap<String, CpuSample> = BTreeMap::new();
    let mut next_draw = Instant::now();
    loop {
        ports.stats.drain(|s| {
            collector.record(s);
            let role = read_name(&s.process).into_owned();
            let now = Instant::now();
            let sample = cpu.entry(role.clone()).or_default();
            if sample.pid == s.pid
                && let Some((t, c)) = sample.last
            {
                let dt = now.duration_since(t).as_secs_f64();
                if dt > 0.0 {
                    sample.percent = 100.0 * (s.cpu_ns.saturating_sub(c)) as f64 / 1e9 / dt;
                }
            }
            sample.pid = s.pid;
            sample.last = Some((now, s.cpu_ns));
            sample.rss_mib = s.max_rss_bytes as f64 / (1024.0 * 1024.0);
            latest.insert(role, Box::new(*s));
        });
        ports.processes.update();
        ports.status.update();
        if shutdown.load(Ordering::SeqCst) || terminal.as_ref().is_some_and(|t| t.quit_requested())
        {
            return Ok(());
        }
        if args.once && started.elapsed() < Duration::from_secs(2) {
            std::thread::sleep(Duration::from_millis(50));
            continue;
        }
        if Instant::now() >= next_draw || args.once {
            next_draw = Instant::now() + Duration::from_secs(1);
            let screen = render(args, &ports, &latest, &cpu);
            let mut out = std::io::stdout().lock();
            if !args.once {
                let _ = write!(out, "\x1b[2J\x1b[H");
            }
            let _ = write!(out, "{screen}");
            let _ = out.flush();
            if args.once {
                return Ok(());
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn render(
    args: &TopArgs,
    ports: &Ports,
    latest: &BTreeMap<String, Box<Stats>>,
    cpu: &BTreeMap<String, CpuSample>,
) -> String {
    let mut s = String::new();
    let _ = write!(s, "mole top — namespace {}", args.namespace);
    if let Some(status) = ports.status.latest() {
        let _ = write!(
            s,
            "   tick {}   coverage {:.1}%   loop p50 {:.0} µs p99 {:.0} µs",
            status.header.tick,
            status.coverage * 100.0,
            status.loop_p50_us,
            status.loop_p99_us
        );
    }
    let _ = writeln!(s, "{}", if args.once { "" } else { "   (q to quit)" });
    let _ = writeln!(
        s,
        "\n{:<14} {:>8} {:<11} {:>8} {:>7} {:>9}",
        "process", "pid", "state", "restarts", "cpu %", "rss MiB"
    );
    let supervised: Vec<_> = ports
        .processes
        .latest()
        .map(|p| p.processes().to_vec())
        .unwrap_or_default();
    let roles = listed_roles(
        supervised.iter().map(|p| read_name(&p.role).into_owned()),
        latest.keys().cloned(),
    );
    for role in &roles {
        let sup = supervised
            .iter()
            .find(|p| read_name(&p.role) == role.as_str());
        let sample = cpu.get(role);
        let _ = writeln!(
            s,
            "{:<14} {:>8} {:<11} {:>8} {:>7.1} {:>9.1}",
            role,
            sup.map_or(sample.map_or(0, |c| c.pid), |p| p.pid),
            sup.map_or("-", |p| state_name(p.state)),
            sup.map_or(0, |p| p.restarts),
            sample.map_or(0.0, |c| c.percent),
            sample.map_or(0.0, |c| c.rss_mib),
        );
    }
    let _ = writeln!(
        s,
        "\n{:<24} {:<14} {:>8} {:>10} {:>10} {:>8} {:>8}",
        "topic", "at", "rate Hz", "p50 µs", "p99 µs", "dropped", "invalid"
    );
    for (role, stats) in latest {
        for t in stats.topics() {
            if t.direction != mole_types::DIRECTION_SUBSCRIBE {
                continue;
            }
            let _ = writeln!(
                s,
                "{:<24} {:<14} {:>8.1} {:>10.1} {:>10.1} {:>8} {:>8}",
                read_name(&t.topic),
                role,
                t.rate_hz,
                t.latency_p50_us,
                t.latency_p99_us,
                t.dropped,
                t.invalid
            );
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every graph role has a row, in the graph's order, even before it is heard from; other
    /// processes follow; the launcher and `mole top` do not.
    #[test]
    fn the_process_table_lists_the_graph_first() {
        let extra = mole_types::graph::nodes::RECORDER.to_owned();
        let roles = listed_roles(
            [GRAPH[2].role.name().to_owned(), extra.clone()],
            [nodes::LAUNCHER.to_owned(), nodes::TOP.to_owned()],
        );
        let graph: Vec<String> = GRAPH.iter().map(|r| r.role.name().to_owned()).collect();
        assert_eq!(roles[..GRAPH.len()], graph[..]);
        assert_eq!(roles[GRAPH.len()..], [extra]);
    }
}
