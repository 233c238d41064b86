//! zenoh's latency and throughput on loopback TCP between two processes, for `mole bench ipc`
//! (run by the `mole-zenoh-bench` binary, which starts a copy of itself as the echo).
//!
//! This process listens on `tcp/127.0.0.1:<free port>`, the echo connects to it; both are peers
//! that find nobody by multicast, and every sample goes with CongestionControl::Block and
//! express. Latency: ping → echo → pong, one at a time. Throughput: one publisher flat out for a
//! fixed time; the echo counts what arrives and answers with its count at the end marker.

use crate::Failed;
use serde_json::json;
use std::io::Read as _;
use std::process::{Child, Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};
use zenoh::Wait;
use zenoh::bytes::ZBytes;
use zenoh::qos::CongestionControl;

/// The attachment that ends a throughput flood.
const END: &[u8] = b"end";

/// What the benchmark measures (the command line's settings).
#[derive(Debug, Clone)]
pub struct BenchPlan<'a> {
    /// Payload sizes in bytes.
    pub sizes: &'a [usize],
    /// Measured round trips per size below 1 MiB.
    pub samples: usize,
    /// Measured round trips per size at 1 MiB and above.
    pub samples_large: usize,
    /// How long the throughput publisher sends, at the largest size (s).
    pub throughput_secs: f64,
    /// How long to wait for one answer of the echo before giving up (ms).
    pub timeout_ms: u64,
}

/// A peer session that listens on `listen` or connects to `connect`, scouting nobody.
fn open_session(listen: &[&str], connect: &[&str]) -> Result<zenoh::Session, Failed> {
    let config = json!({
        "mode": "peer",
        "listen": { "endpoints": listen },
        "connect": { "endpoints": connect },
        "scouting": { "multicast": { "enabled": false }, "gossip": { "enabled": false } },
    });
    let config = zenoh::Config::from_json5(&config.to_string())?;
    zenoh::open(config).wait()
}

/// A publisher as the benchmark sends: reliable (Block) and express.
fn publisher(
    session: &zenoh::Session,
    key: String,
) -> Result<zenoh::pubsub::Publisher<'static>, Failed> {
    session
        .declare_publisher(key)
        .congestion_control(CongestionControl::Block)
        .express(true)
        .wait()
}

/// Checks the settings before any session opens.
fn validate(args: &BenchPlan) -> Result<(), Failed> {
    if args.sizes.is_empty() || args.sizes.contains(&0) {
        return Err("the sizes must be at least one, each at least 1 byte".into());
    }
    if args.samples == 0 || args.samples_large == 0 {
        return Err("every sample count must be at least 1".into());
    }
    if !(args.throughput_secs.is_finite() && args.throughput_secs > 0.0) {
        return Err("the throughput duration must be positive".into());
    }
    if args.timeout_ms == 0 {
        return Err("the timeout must be positive".into());
    }
    Ok(())
}

/// The echo process, killed when the benchmark ends (or closes its standard input).
struct EchoChild(Child);

impl Drop for EchoChild {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Measures latency per size and throughput at the largest, returns the report.
pub fn bench(args: &BenchPlan) -> Result<serde_json::Value, Failed> {
    validate(args)?;
    let prefix = format!("mole-bench/zenoh/{}", std::process::id());
    // Any free port: the echo connects to the one zenoh bound.
    let session = open_session(&["tcp/127.0.0.1:0"], &[])?;
    let endpoint = session
        .info()
        .locators()
        .wait()
        .first()
        .map(ToString::to_string)
        .ok_or("the session listens nowhere")?;
    let ping = publisher(&session, format!("{prefix}/ping"))?;
    let pong = session
        .declare_subscriber(format!("{prefix}/pong"))
        .wait()?;
    let flood = publisher(&session, format!("{prefix}/flood"))?;
    let count = session
        .declare_subscriber(format!("{prefix}/count"))
        .wait()?;
    let _echo = EchoChild(
        Command::new(std::env::current_exe()?)
            .args(["--echo-of", &endpoint, "--prefix", &prefix])
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .spawn()?,
    );
    let timeout = Duration::from_millis(args.timeout_ms);
    let mut pinger = Pinger {
        ping: &ping,
        pong: &pong,
        seq: 0,
        timeout,
    };
    pinger.until_answered(Duration::from_secs(10) + timeout)?;

    let mut latency = Vec::new();
    for &size in args.sizes {
        let payload = ZBytes::from(vec![0u8; size]);
        let samples = if size >= 1 << 20 {
            args.samples_large
        } else {
            args.samples
        };
        for _ in 0..samples.div_ceil(10) {
            pinger.round_trip(&payload)?;
        }
        let one_way_ns = (0..samples)
            .map(|_| pinger.round_trip(&payload).map(|rtt| rtt / 2))
            .collect::<Result<Vec<u64>, Failed>>()?;
        latency.push(json!({ "size": size, "one_way_ns": one_way_ns }));
    }

    let size = args.sizes.iter().copied().max().unwrap_or(64);
    let payload = ZBytes::from(vec![0u8; size]);
    let start = Instant::now();
    let run = Duration::from_secs_f64(args.throughput_secs);
    let mut sent = 0u64;
    while start.elapsed() < run {
        flood.put(payload.clone()).wait()?;
        sent += 1;
    }
    let send_ns = start.elapsed().as_nanos() as u64;
    flood.put(ZBytes::new()).attachment(END).wait()?;
    let answer = count
        .recv_timeout(timeout + run)?
        .ok_or("the echo did not report its count")?;
    let counted: serde_json::Value = serde_json::from_slice(&answer.payload().to_bytes())
        .map_err(|e| format!("the echo's count: {e}"))?;
    Ok(json!({
        "setup": format!(
            "two processes, two zenoh 1.10 peer sessions over {endpoint} (multicast scouting \
             off), CongestionControl::Block, express; latency = round trip / 2, one ping at a time"
        ),
        "latency": latency,
        "throughput": {
            "size": size,
            "sent": sent,
            "send_ns": send_ns,
            "received": counted["received"],
            "span_ns": counted["span_ns"],
        },
    }))
}

/// Sends pings one at a time and waits for each one's pong.
struct Pinger<'a> {
    ping: &'a zenoh::pubsub::Publisher<'static>,
    pong: &'a zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
    seq: u64,
    timeout: Duration,
}

impl Pinger<'_> {
    /// One ping out and its pong back: the round trip (ns). Pongs of earlier pings are skipped.
    fn round_trip(&mut self, payload: &ZBytes) -> Result<u64, Failed> {
        self.seq += 1;
        let start = Instant::now();
        self.ping
            .put(payload.clone())
            .attachment(self.seq.to_le_bytes().to_vec())
            .wait()?;
        loop {
            let left = self.timeout.saturating_sub(start.elapsed());
            let Some(sample) = self.pong.recv_timeout(left)? else {
                return Err(format!(
                    "no pong from the echo in {} ms ({} B)",
                    self.timeout.as_millis(),
                    payload.len()
                )
                .into());
            };
            let seq = sample
                .attachment()
                .map(|a| a.to_bytes())
                .and_then(|a| <[u8; 8]>::try_from(a.as_ref()).ok())
                .map(u64::from_le_bytes);
            if seq == Some(self.seq) {
                return Ok(start.elapsed().as_nanos() as u64);
            }
        }
    }

    /// Pings until the echo answers (it connects and subscribes after this side listens).
    fn until_answered(&mut self, patience: Duration) -> Result<(), Failed> {
        let start = Instant::now();
        let wait = self.timeout;
        self.timeout = Duration::from_millis(100);
        let tiny = ZBytes::from(vec![0u8; 8]);
        let answered = loop {
            if self.round_trip(&tiny).is_ok() {
                break true;
            }
            if start.elapsed() > patience {
                break false;
            }
        };
        self.timeout = wait;
        if answered {
            Ok(())
        } else {
            Err(format!("the echo did not answer in {} s", patience.as_secs()).into())
        }
    }
}

/// What the echo counted of a flood.
#[derive(Default)]
struct Flood {
    received: u64,
    first: Option<Instant>,
    last: Option<Instant>,
}

/// Answers every ping with its payload and attachment, counts floods; ends when the benchmark
/// closes its standard input.
pub fn echo(endpoint: &str, prefix: &str) -> Result<(), Failed> {
    let session = open_session(&[], &[endpoint])?;
    let pong = publisher(&session, format!("{prefix}/pong"))?;
    let _ping = session
        .declare_subscriber(format!("{prefix}/ping"))
        .callback(move |sample| {
            let answer = pong
                .put(sample.payload().clone())
                .attachment(sample.attachment().cloned())
                .wait();
            if let Err(e) = answer {
                eprintln!("mole-zenoh-bench echo: cannot answer a ping: {e}");
            }
        })
        .wait()?;
    let count = publisher(&session, format!("{prefix}/count"))?;
    let flood = Mutex::new(Flood::default());
    let _flood = session
        .declare_subscriber(format!("{prefix}/flood"))
        .callback(move |sample| {
            let mut flood = flood.lock().unwrap_or_else(|e| e.into_inner());
            let now = Instant::now();
            if sample
                .attachment()
                .is_none_or(|a| a.to_bytes().as_ref() != END)
            {
                flood.received += 1;
                flood.first.get_or_insert(now);
                flood.last = Some(now);
                return;
            }
            let done = std::mem::take(&mut *flood);
            let span_ns = match (done.first, done.last) {
                (Some(first), Some(last)) => (last - first).as_nanos() as u64,
                _ => 0,
            };
            let report = json!({ "received": done.received, "span_ns": span_ns }).to_string();
            if let Err(e) = count.put(report).wait() {
                eprintln!("mole-zenoh-bench echo: cannot report the count: {e}");
            }
        })
        .wait()?;
    // Until the benchmark is done with this process (its end closes the pipe).
    std::io::stdin().read_to_end(&mut Vec::new())?;
    Ok(())
}
