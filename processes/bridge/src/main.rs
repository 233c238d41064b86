//! The bridge: chosen topics of this namespace out to a peer stack over zenoh, and the peer's
//! topics in, so that one stack runs on two machines.
//!
//! out: iceoryx2 subscriber (wakes the bridge) → zenoh publisher on `mole/<ns>/<topic>`, the
//!      message's layout attached; a topic with history also answers queries with its newest.
//! in:  zenoh subscriber on `mole/<peer>/<topic>` → one inbox in arrival order (zenoh's thread
//!      rings this node's doorbell) → checked ([`mole_bridge::Forwarding`]) → mole publisher here.
//! link: a liveliness token `mole/<ns>/bridge/<peer>` ([`mole_bridge::LinkWatch`]); the peer's
//!      going and coming back is reported, and on its return the topics with history are asked
//!      for again; a bridge of other namespaces on the link is reported with both.
//!
//! Ready (its first statistics, which the launcher waits for) only once the peer is there, so
//! a stack whose world depends on its bridge starts stepping with both halves listening; a peer
//! not there within [`mole_types::link::PEER_TIMEOUT`] ends the bridge (exit 2) with what it saw
//! on the link. Where it listens (port 0: the port it got) is logged and written to
//! [`mole_types::link::LISTENING_FILE`] in the run's output directory; a restart listens there
//! again.

use clap::Parser;
use mole_bridge::{Failed, Ins, Link, Outs, ROLE, listen_again, open_session, spec_of};
use mole_runtime::{CommonArgs, Context, Wake};
use mole_types::env;
use std::path::PathBuf;
use std::process::ExitCode;

/// mole's bridge: topics of a namespace to and from a stack on another machine, over zenoh
#[derive(Debug, Parser)]
struct Args {
    #[command(flatten)]
    common: CommonArgs,
    /// The namespace of the stack on the other side (its topics are read under its keys).
    #[arg(long)]
    peer_namespace: String,
    /// A topic published here and sent to the peer (repeat for more).
    #[arg(long = "out")]
    out: Vec<String>,
    /// A topic the peer publishes, published here (repeat for more).
    #[arg(long = "in")]
    inbound: Vec<String>,
    /// A zenoh endpoint to listen on: tcp/HOST:PORT or tls/HOST:PORT (repeat for more).
    #[arg(long)]
    listen: Vec<String>,
    /// A zenoh endpoint to connect to (repeat for more); tried again until the peer is there.
    #[arg(long)]
    connect: Vec<String>,
    /// TLS: the certificate authority both sides trust (PEM).
    #[arg(long, requires_all = ["tls_cert", "tls_key"])]
    tls_root_ca: Option<PathBuf>,
    /// TLS: this side's certificate (PEM).
    #[arg(long, requires = "tls_root_ca")]
    tls_cert: Option<PathBuf>,
    /// TLS: this side's private key (PEM).
    #[arg(long, requires = "tls_root_ca")]
    tls_key: Option<PathBuf>,
    /// The run's output directory: where it listens is written there (bridge-listening.txt).
    #[arg(long = "out-dir", env = env::OUT)]
    out_dir: Option<PathBuf>,
}

fn main() -> ExitCode {
    mole_runtime::exit_code(run(&Args::parse()).map_err(|e| e as Box<dyn std::error::Error>))
}

fn run(args: &Args) -> Result<(), Failed> {
    let mut spec = spec_of(
        &args.common.namespace,
        &args.peer_namespace,
        [&args.out, &args.inbound],
        [&args.listen, &args.connect],
        [&args.tls_root_ca, &args.tls_cert, &args.tls_key],
    )?;
    let listening = listen_again(&mut spec, args.out_dir.as_deref());
    let mut ctx = Context::new(ROLE, &args.common)?;
    let session = open_session(&mut spec, listening.as_deref())?;
    let ringer = ctx.ringer()?;
    let link = Link::watch(&session, &spec, &ringer)?;
    let mut outs = Outs::open(&ctx, &session, &spec)?;
    let mut ins = Ins::open(&ctx, &session, &spec, &ringer)?;
    let _token = link.declare_token(&session)?;
    if !link.wait_for_peer(&ctx, &spec)? {
        return Ok(());
    }
    ins.ask_history(&session);
    ctx.ready();

    let waitset = ctx.waitset()?;
    let wakers = outs.wakers();
    let _attached = waitset.attach_all(&wakers)?;
    while waitset.wait(&mut ctx, None)? != Wake::Shutdown {
        outs.send_in_order();
        if link.came_back() {
            ins.ask_history(&session);
        }
        ins.forward_waiting()?;
    }
    Ok(())
}
