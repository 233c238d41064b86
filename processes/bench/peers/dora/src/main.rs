//! One process of `mole bench peers`' loop, on dora-rs: the source, which sends a payload round
//! the loop and measures how long it takes to come back, or a stage, which forwards every input.
//!
//! The loop is source → stage → stage → sink → source; the sink is a stage whose output the
//! source takes as its input `back`. The source reports to `mole bench peers` over a Unix socket
//! (`--marks`): `start` when the warm-up is over (it waits for `go`, so the bench can read the
//! CPU clocks of every process first), then `end <elapsed_ns> <loops>` and one latency per line,
//! and waits for `ok`. The first eight bytes of the payload are the sequence number.

use dora_node_api::dora_core::config::DataId;
use dora_node_api::{DoraNode, Event};
use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::UnixStream;
use std::time::Instant;

type Failure = Box<dyn std::error::Error>;

/// The command line: `source --size N --warm N --loops N --paced --marks PATH --timeout-ms T` or
/// `forward --size N`.
struct Args {
    source: bool,
    size: usize,
    warm: u64,
    loops: u64,
    paced: bool,
    marks: String,
    /// How long one loop may take before the source gives up (a stage is gone).
    timeout: std::time::Duration,
}

fn parse_args() -> Result<Args, Failure> {
    let mut argv = std::env::args().skip(1);
    let role = argv
        .next()
        .ok_or("usage: mole-dora-peer source|forward [options]")?;
    let mut args = Args {
        source: match role.as_str() {
            "source" => true,
            "forward" => false,
            other => return Err(format!("unknown role `{other}` (source or forward)").into()),
        },
        size: 64,
        warm: 100,
        loops: 1000,
        paced: false,
        marks: String::new(),
        timeout: std::time::Duration::from_secs(5),
    };
    while let Some(flag) = argv.next() {
        let mut value = || argv.next().ok_or(format!("{flag} needs a value"));
        match flag.as_str() {
            "--size" => args.size = value()?.parse()?,
            "--warm" => args.warm = value()?.parse()?,
            "--loops" => args.loops = value()?.parse()?,
            "--marks" => args.marks = value()?,
            "--timeout-ms" => {
                args.timeout = std::time::Duration::from_millis(value()?.parse()?);
            }
            "--paced" => args.paced = true,
            other => return Err(format!("unknown option `{other}`").into()),
        }
    }
    if args.size < 8 {
        return Err("--size must be at least 8 bytes (the sequence number)".into());
    }
    Ok(args)
}

fn main() -> Result<(), Failure> {
    let args = parse_args()?;
    let (node, events) = DoraNode::init_from_env().map_err(|e| format!("dora init: {e}"))?;
    if args.source {
        source(&args, node, events)
    } else {
        forward(args.size, node, events)
    }
}

/// Forwards every input's bytes on `out` (dora's API has no way to pass a received sample on:
/// each stage writes a new one, as a stage that transforms its input would).
fn forward(
    size: usize,
    mut node: DoraNode,
    mut events: dora_node_api::EventStream,
) -> Result<(), Failure> {
    let out = DataId::from("out".to_string());
    while let Some(event) = events.recv() {
        match event {
            Event::Input { metadata, data, .. } => {
                let bytes: &[u8] = (&data).try_into().map_err(|e| format!("input: {e}"))?;
                if bytes.len() != size {
                    return Err(format!("input of {} bytes, expected {size}", bytes.len()).into());
                }
                node.send_output_raw(out.clone(), metadata.parameters, size, |buf| {
                    buf.copy_from_slice(bytes)
                })
                .map_err(|e| format!("send: {e}"))?;
            }
            Event::Stop(_) => break,
            _ => {}
        }
    }
    Ok(())
}

/// Sends `warm + loops` payloads round the loop, one in flight: on each timer tick when paced,
/// else each as soon as the previous came back (the first on a tick). Reports over `--marks`.
fn source(
    args: &Args,
    mut node: DoraNode,
    mut events: dora_node_api::EventStream,
) -> Result<(), Failure> {
    let out = DataId::from("out".to_string());
    let mut marks = UnixStream::connect(&args.marks).map_err(|e| format!("{}: {e}", args.marks))?;
    let mut replies = BufReader::new(marks.try_clone()?);
    let mut reply = String::new();
    let mut expect = |replies: &mut BufReader<UnixStream>, word: &str| -> Result<(), Failure> {
        reply.clear();
        replies.read_line(&mut reply)?;
        if reply.trim() == word {
            Ok(())
        } else {
            Err(format!("expected `{word}` from the bench, got `{}`", reply.trim()).into())
        }
    };
    let mut latencies: Vec<u64> = Vec::with_capacity(args.loops as usize);
    let total = args.warm + args.loops;
    let (mut seq, mut sent_at): (u64, Option<Instant>) = (0, None);
    let mut measured_from = Instant::now();
    let send = |node: &mut DoraNode, seq: u64| {
        node.send_output_raw(out.clone(), Default::default(), args.size, |buf| {
            buf[..8].copy_from_slice(&seq.to_le_bytes());
            buf[8..].fill(0);
        })
        .map_err(|e| format!("send: {e}"))
    };
    if args.warm == 0 {
        writeln!(marks, "start")?;
        expect(&mut replies, "go")?;
        measured_from = Instant::now();
    }
    while let Some(event) = events.recv() {
        match event {
            Event::Input { id, .. } if id.as_str() == "tick" => {
                if let Some(sent) = sent_at
                    && sent.elapsed() > args.timeout
                {
                    // The bench reads the closed socket as the failure, with dora's log.
                    return Err(format!(
                        "loop {seq} did not come back within {:?}: a stage is gone",
                        args.timeout
                    )
                    .into());
                }
                if sent_at.is_none() && (args.paced || seq == 0) {
                    sent_at = Some(Instant::now());
                    send(&mut node, seq)?;
                }
            }
            Event::Input { id, data, .. } if id.as_str() == "back" => {
                let received = Instant::now();
                let bytes: &[u8] = (&data).try_into().map_err(|e| format!("input: {e}"))?;
                let back = u64::from_le_bytes(bytes[..8].try_into()?);
                let Some(sent) = sent_at.filter(|_| back == seq) else {
                    return Err(format!("payload {back} came back, {seq} was in flight").into());
                };
                if seq >= args.warm {
                    latencies.push((received - sent).as_nanos() as u64);
                }
                seq += 1;
                sent_at = None;
                if seq == args.warm {
                    writeln!(marks, "start")?;
                    expect(&mut replies, "go")?;
                    measured_from = Instant::now();
                }
                if seq == total {
                    let elapsed = measured_from.elapsed().as_nanos();
                    writeln!(marks, "end {elapsed} {}", latencies.len())?;
                    let mut text = String::with_capacity(latencies.len() * 8);
                    for l in &latencies {
                        text.push_str(&l.to_string());
                        text.push('\n');
                    }
                    marks.write_all(text.as_bytes())?;
                    expect(&mut replies, "ok")?;
                    return Ok(());
                }
                if !args.paced {
                    sent_at = Some(Instant::now());
                    send(&mut node, seq)?;
                }
            }
            Event::Stop(_) => return Err("stopped before the loops were done".into()),
            _ => {}
        }
    }
    Err("the event stream ended before the loops were done".into())
}
