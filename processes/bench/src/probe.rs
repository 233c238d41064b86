//! The probe process's side: its command line, its ports, and the role it plays.

use crate::floor::PipePair;
use crate::link::{self, Link, PortSpec, Ports, StreamLink};
use crate::messages::with_message_type;
use crate::{BenchError, ProbeKind, Transport, WakeMode, roles};
use std::os::fd::AsFd;
use std::time::{Duration, Instant};

/// How long a probe tries to connect its socket to the driver.
const CONNECT_TIMEOUT: Duration = Duration::from_secs(10);

/// Latency: one subscriber.
pub(crate) const PING: PortSpec = PortSpec {
    name: "bench/ping",
    buffer: 2,
    max_publishers: 1,
    max_subscribers: 1,
};
/// Fan-out: up to [`crate::MAX_FANOUT`] subscribers.
pub(crate) const FANOUT: PortSpec = PortSpec {
    name: "bench/fanout",
    buffer: 2,
    max_publishers: 1,
    max_subscribers: crate::MAX_FANOUT,
};
/// Throughput: a deeper queue, so the subscriber loses less while it catches up.
pub(crate) const FLOOD: PortSpec = PortSpec {
    name: "bench/flood",
    buffer: 16,
    max_publishers: 1,
    max_subscribers: 1,
};
/// Acknowledgements from every probe of a group.
pub(crate) const ACK: PortSpec = PortSpec {
    name: "bench/ack",
    buffer: 64,
    max_publishers: crate::MAX_FANOUT,
    max_subscribers: 1,
};
/// Hops of the event chain.
pub(crate) const CHAIN_HOPS: usize = 5;
const CHAIN_NAMES: [&str; CHAIN_HOPS + 1] = [
    "bench/chain/0",
    "bench/chain/1",
    "bench/chain/2",
    "bench/chain/3",
    "bench/chain/4",
    "bench/chain/5",
];

/// Forwarding processes of `mole bench peers`' loop: two stages and the sink that closes it.
pub(crate) const LOOP_STAGES: usize = 3;
const LOOP_NAMES: [&str; LOOP_STAGES + 1] = [
    "bench/loop/0",
    "bench/loop/1",
    "bench/loop/2",
    "bench/loop/3",
];

/// Topic `i` of a chain of hops named `names` (one more topic than hops).
fn hop_topic(names: &'static [&'static str], i: usize) -> PortSpec {
    PortSpec {
        name: names[i.min(names.len() - 1)],
        buffer: 2,
        max_publishers: 1,
        max_subscribers: 1,
    }
}

/// The topics of the loop, else of the chain: one more than its hops.
fn hop_names(kind: ProbeKind) -> &'static [&'static str] {
    match kind {
        ProbeKind::Loop => &LOOP_NAMES,
        _ => &CHAIN_NAMES,
    }
}

/// The driver's ports for a measurement.
pub(crate) fn driver_ports(kind: ProbeKind) -> Ports {
    let (data_out, data_in, ack_in) = match kind {
        ProbeKind::Latency => (PING, None, Some(ACK)),
        ProbeKind::Fanout => (FANOUT, None, Some(ACK)),
        ProbeKind::Throughput => (FLOOD, None, Some(ACK)),
        ProbeKind::Chain | ProbeKind::Loop => {
            let names = hop_names(kind);
            (
                hop_topic(names, 0),
                Some(hop_topic(names, names.len() - 1)),
                None,
            )
        }
    };
    Ports {
        data_out: Some(data_out),
        data_in,
        ack_out: None,
        ack_in,
    }
}

/// Probe `id`'s ports for a measurement.
pub(crate) fn probe_ports(kind: ProbeKind, id: usize) -> Result<Ports, BenchError> {
    let echo = |data_in| Ports {
        data_in: Some(data_in),
        ack_out: Some(ACK),
        ..Ports::default()
    };
    Ok(match kind {
        ProbeKind::Latency => echo(PING),
        ProbeKind::Fanout => echo(FANOUT),
        ProbeKind::Throughput => echo(FLOOD),
        ProbeKind::Chain | ProbeKind::Loop => {
            let names = hop_names(kind);
            let hops = names.len() - 1;
            if id >= hops {
                return Err(BenchError::Config(format!(
                    "hop {id} does not exist (0..{hops})"
                )));
            }
            Ports {
                data_in: Some(hop_topic(names, id)),
                data_out: Some(hop_topic(names, id + 1)),
                ..Ports::default()
            }
        }
    })
}

/// The probe's command line (the driver builds it; `mole-bench-probe --help` documents it).
#[derive(Debug, Clone, PartialEq, Eq, clap::Parser)]
#[command(
    name = "mole-bench-probe",
    about = "A probe process of `mole bench ipc` (started by the driver)"
)]
pub struct ProbeArgs {
    /// Namespace of the probe group (services `mole/<namespace>/bench/...`).
    #[arg(long)]
    pub namespace: String,
    #[arg(long, value_enum)]
    pub transport: Transport,
    #[arg(long, value_enum)]
    pub kind: ProbeKind,
    /// Message size in bytes.
    #[arg(long)]
    pub size: usize,
    #[arg(long, value_enum)]
    pub wake: WakeMode,
    /// This probe's index in its group (fan-out) or its hop (chain).
    #[arg(long, default_value_t = 0)]
    pub id: u32,
    /// Sockets: the Unix socket path or the TCP `127.0.0.1:<port>` to connect to (a pipe probe
    /// reads its standard input and writes its standard output).
    #[arg(long)]
    pub address: Option<String>,
    /// Exit with an error after this long without a message (ms): the driver is gone (a pipe
    /// probe instead ends when the driver's end of its pipe closes).
    #[arg(long, default_value_t = 30_000)]
    pub idle_ms: u64,
}

impl ProbeArgs {
    /// The command-line arguments that parse back into these.
    pub fn to_args(&self) -> Vec<String> {
        use clap::ValueEnum;
        let name = |v: Option<clap::builder::PossibleValue>| {
            v.map(|p| p.get_name().to_string()).unwrap_or_default()
        };
        let mut args = vec![
            "--namespace".to_string(),
            self.namespace.clone(),
            "--transport".to_string(),
            name(self.transport.to_possible_value()),
            "--kind".to_string(),
            name(self.kind.to_possible_value()),
            "--size".to_string(),
            self.size.to_string(),
            "--wake".to_string(),
            name(self.wake.to_possible_value()),
            "--id".to_string(),
            self.id.to_string(),
            "--idle-ms".to_string(),
            self.idle_ms.to_string(),
        ];
        if let Some(address) = &self.address {
            args.push("--address".to_string());
            args.push(address.clone());
        }
        args
    }
}

fn connect<S>(
    address: &str,
    mut try_connect: impl FnMut(&str) -> std::io::Result<S>,
) -> Result<S, BenchError> {
    let deadline = Instant::now() + CONNECT_TIMEOUT;
    loop {
        match try_connect(address) {
            Ok(stream) => return Ok(stream),
            Err(e) if Instant::now() >= deadline => {
                return Err(BenchError::Io {
                    what: "probe cannot connect to the driver",
                    source: e,
                });
            }
            Err(_) => std::thread::sleep(Duration::from_millis(5)),
        }
    }
}

/// Runs one probe until the driver's stop message (or an error, or `idle_ms` without a message).
pub fn run_probe(args: &ProbeArgs) -> Result<(), BenchError> {
    let idle = Duration::from_millis(args.idle_ms.max(1));
    let (kind, id) = (args.kind, args.id);
    let role = move |link: &mut dyn Link| match kind {
        ProbeKind::Latency | ProbeKind::Fanout => roles::echo(link, id, false, idle),
        ProbeKind::Throughput => roles::echo(link, id, true, idle),
        ProbeKind::Chain | ProbeKind::Loop => roles::hop(link, idle),
    };
    let ports = probe_ports(kind, id as usize)?;
    let role_name = format!("probe{id}");
    let address = || {
        args.address
            .as_deref()
            .ok_or_else(|| BenchError::Config("a socket probe needs --address".to_string()))
    };
    let io = |what: &'static str| move |source| BenchError::Io { what, source };
    match args.transport {
        Transport::Runtime => with_message_type!(args.size, M => link::with_runtime::<M, ()>(
            &args.namespace, &role_name, &ports, args.wake, role
        )),
        Transport::Raw => with_message_type!(args.size, M => link::with_raw::<M, ()>(
            &args.namespace, &role_name, &ports, args.wake, role
        )),
        Transport::Unix => {
            let stream = connect(address()?, |a| std::os::unix::net::UnixStream::connect(a))?;
            stream
                .set_read_timeout(Some(idle))
                .map_err(io("socket timeout"))?;
            role(&mut StreamLink::new(stream, args.size))
        }
        Transport::Tcp => {
            let stream = connect(address()?, |a| std::net::TcpStream::connect(a))?;
            stream.set_nodelay(true).map_err(io("TCP_NODELAY"))?;
            stream
                .set_read_timeout(Some(idle))
                .map_err(io("socket timeout"))?;
            role(&mut StreamLink::new(stream, args.size))
        }
        Transport::Pipe => {
            let own = |fd: std::os::fd::BorrowedFd<'_>| {
                fd.try_clone_to_owned()
                    .map(std::fs::File::from)
                    .map_err(io("probe pipe"))
            };
            let rx = own(std::io::stdin().as_fd())?;
            let tx = own(std::io::stdout().as_fd())?;
            role(&mut StreamLink::new(PipePair::new(rx, tx, None), args.size))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[test]
    fn probe_arguments_round_trip_through_the_command_line() {
        let args = ProbeArgs {
            namespace: "b1-3".into(),
            transport: Transport::Raw,
            kind: ProbeKind::Chain,
            size: 1024,
            wake: WakeMode::Event,
            id: 4,
            address: Some("/tmp/x.sock".into()),
            idle_ms: 500,
        };
        let mut argv = vec!["mole-bench-probe".to_string()];
        argv.extend(args.to_args());
        assert_eq!(ProbeArgs::try_parse_from(argv).expect("parses"), args);
    }

    #[test]
    fn driver_and_probes_agree_on_every_service() {
        for kind in [ProbeKind::Latency, ProbeKind::Fanout, ProbeKind::Throughput] {
            let d = driver_ports(kind);
            let p = probe_ports(kind, 0).expect("ports");
            assert_eq!(d.data_out.map(|s| s.name), p.data_in.map(|s| s.name));
            assert_eq!(d.ack_in.map(|s| s.name), p.ack_out.map(|s| s.name));
        }
        let d = driver_ports(ProbeKind::Chain);
        let first = probe_ports(ProbeKind::Chain, 0).expect("hop 0");
        let last = probe_ports(ProbeKind::Chain, CHAIN_HOPS - 1).expect("last hop");
        assert_eq!(d.data_out.map(|s| s.name), first.data_in.map(|s| s.name));
        assert_eq!(d.data_in.map(|s| s.name), last.data_out.map(|s| s.name));
        assert!(probe_ports(ProbeKind::Chain, CHAIN_HOPS).is_err());
        let d = driver_ports(ProbeKind::Loop);
        let first = probe_ports(ProbeKind::Loop, 0).expect("first stage");
        let sink = probe_ports(ProbeKind::Loop, LOOP_STAGES - 1).expect("sink");
        assert_eq!(d.data_out.map(|s| s.name), first.data_in.map(|s| s.name));
        assert_eq!(d.data_in.map(|s| s.name), sink.data_out.map(|s| s.name));
        assert!(probe_ports(ProbeKind::Loop, LOOP_STAGES).is_err());
    }

    #[test]
    fn an_unsupported_size_fails_before_opening_anything() {
        let args = ProbeArgs {
            namespace: "unused".into(),
            transport: Transport::Runtime,
            kind: ProbeKind::Latency,
            size: 100,
            wake: WakeMode::Busy,
            id: 0,
            address: None,
            idle_ms: 10,
        };
        assert!(matches!(
            run_probe(&args),
            Err(BenchError::UnsupportedSize(100))
        ));
    }
}
