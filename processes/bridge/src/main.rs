//! The bridge: chosen topics of this namespace out to a peer stack over zenoh, and the peer's
//! topics in, so that one stack runs on two machines.
//!
//! out: iceoryx2 subscriber (wakes the bridge) → zenoh publisher on `mole/<ns>/<topic>`, the
//!      message's layout attached; a topic with history also answers queries with its newest.
//! in:  zenoh subscriber on `mole/<peer>/<topic>` → one inbox in arrival order (zenoh's thread
//!      rings this node's doorbell) → checked ([`Forwarding`]) → mole publisher here.
//! link: a liveliness token `mole/<ns>/bridge/<peer>` ([`LinkWatch`]); the peer's going and
//!      coming back is reported, and on its return the topics with history are asked for again;
//!      a bridge of other namespaces on the link is reported with both.
//!
//! Ready (its first statistics, which the launcher waits for) only once the peer is there, so
//! a stack whose world depends on its bridge starts stepping with both halves listening; a peer
//! not there within [`PEER_TIMEOUT`] ends the bridge (exit 2) with what it saw on the link.
//! Where it listens (port 0: the port it got) is logged and written to [`LISTENING_FILE`] in
//! the run's output directory; a restart listens there again.

use clap::Parser;
use mole_bridge::{
    BridgeSpec, Delivery, Entry, Forward, Forwarding, LISTENING, LinkChange, LinkWatch, Outbound,
    Staged, Tls, delivery, descriptor, every_link_token, key_expr, send_in_order,
};
use mole_runtime::{BadInput, CommonArgs, Context, Publisher, Ringer, Subscriber};
use mole_runtime::{Wake, Waker, layout_mismatch};
use mole_types::link::{LISTENING_FILE, PEER_TIMEOUT};
use mole_types::topics::{self, TopicVisitor};
use mole_types::{Message, Topic, env};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait;
use zenoh::bytes::ZBytes;
use zenoh::qos::{CongestionControl, Priority};
use zenoh::sample::{Sample, SampleKind};

/// Why the bridge stopped (zenoh's errors are `Send + Sync`, so all are).
type Failed = Box<dyn std::error::Error + Send + Sync>;

/// The bridge's role (node `mole/<ns>/bridge`, log `bridge.log`).
const ROLE: &str = "bridge";

#[derive(Debug, Parser)]
#[command(
    name = "mole-bridge",
    about = "mole's bridge: topics of a namespace to and from a stack on another machine, over zenoh"
)]
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
    let mut spec = spec_of(args)?;
    let listening = args.out_dir.as_ref().map(|out| out.join(LISTENING_FILE));
    if let Some(again) = listening
        .as_deref()
        .and_then(|file| listen_again(&spec, file))
    {
        spec.listen = again;
    }
    let mut ctx = Context::new(ROLE, &args.common)?;
    let config = zenoh::Config::from_json5(&spec.zenoh_config().to_string())
        .map_err(|e| BadInput(format!("zenoh configuration: {e}")))?;
    let session = zenoh::open(config)
        .wait()
        .map_err(|e| BadInput(format!("cannot open the zenoh session: {e}")))?;
    report_listening(&session, &mut spec, listening.as_deref())?;
    let ringer = ctx.ringer()?;
    let wake = ringer.clone();
    let inbox = Arc::new(Inbox::new(move || wake.ring()));
    let link = Link::watch(&session, &spec, &ringer)?;
    let mut outs = open_outs(&ctx, &session, &spec)?;
    let mut ins = open_ins(&ctx, &session, &spec, &inbox)?;
    let _token = session.liveliness().declare_token(link.own_key()).wait()?;
    tracing::info!(
        peer = %spec.peer_namespace,
        listen = ?spec.listen.iter().map(|e| e.as_str()).collect::<Vec<_>>(),
        connect = ?spec.connect.iter().map(|e| e.as_str()).collect::<Vec<_>>(),
        out = ?spec.out, inbound = ?spec.inbound,
        "waiting for the peer's bridge"
    );
    if !link.wait_for_peer(&ctx, &spec)? {
        return Ok(());
    }
    ask_history(&session, &spec.peer_namespace, &ins, &inbox);
    ctx.ready();

    let waitset = ctx.waitset()?;
    let wakers: Vec<Waker> = outs.iter().map(|o| o.waker()).collect();
    let _attached = waitset.attach_all(&wakers)?;
    let mut staged = Vec::with_capacity(4 * outs.len());
    loop {
        if waitset.wait(&mut ctx, None)? == Wake::Shutdown {
            return Ok(());
        }
        send_in_order(&mut outs, &mut staged);
        if link.came_back() {
            ask_history(&session, &spec.peer_namespace, &ins, &inbox);
        }
        while let Some(entry) = inbox.pop() {
            ins[entry.topic].forward(&entry.item, entry.history)?;
        }
    }
}

/// A restarted bridge's endpoints: where its first start listened (its port 0 resolved), read
/// from `file`, so the other half finds it there again.
fn listen_again(spec: &BridgeSpec, file: &Path) -> Option<Vec<mole_types::link::Endpoint>> {
    if spec.listen.iter().all(|e| e.port() != 0) {
        return None;
    }
    let recorded = std::fs::read_to_string(file).ok()?;
    let again = spec.listening_again(&recorded);
    match &again {
        Some(_) => tracing::info!(
            file = %file.display(),
            "listening again where the first start of this run did"
        ),
        None => tracing::warn!(
            file = %file.display(),
            "not the endpoints of this bridge: listening as configured"
        ),
    }
    again
}

/// Logs where the session listens (port 0 replaced by the port zenoh bound), one
/// "listening on ENDPOINT" line each, and writes them to `file`, one a line, for the other
/// half (replaced whole: a reader never sees half of it).
fn report_listening(
    session: &zenoh::Session,
    spec: &mut BridgeSpec,
    file: Option<&Path>,
) -> Result<(), Failed> {
    if spec.listen.is_empty() {
        return Ok(());
    }
    let locators: Vec<String> = session
        .info()
        .locators()
        .wait()
        .iter()
        .map(ToString::to_string)
        .collect();
    let bound = spec.bound(&locators).ok_or_else(|| {
        BadInput(format!(
            "cannot tell which port zenoh bound for {}: it listens on {}",
            spec.whereabouts(),
            locators.join(", ")
        ))
    })?;
    for endpoint in &bound {
        tracing::info!("{LISTENING} {}", endpoint.as_str());
    }
    spec.listen = bound;
    if let Some(file) = file {
        let text: String = spec
            .listen
            .iter()
            .map(|e| format!("{}\n", e.as_str()))
            .collect();
        let partial = file.with_extension("partial");
        std::fs::write(&partial, text)
            .and_then(|()| std::fs::rename(&partial, file))
            .map_err(|e| BadInput(format!("cannot write {}: {e}", file.display())))?;
    }
    Ok(())
}

/// The checked settings; a bad one is the launch file's (exit 2).
fn spec_of(args: &Args) -> Result<BridgeSpec, BadInput> {
    let tls = match (&args.tls_root_ca, &args.tls_cert, &args.tls_key) {
        (Some(root_ca), Some(cert), Some(key)) => {
            for (what, path) in [
                ("--tls-root-ca", root_ca),
                ("--tls-cert", cert),
                ("--tls-key", key),
            ] {
                if !path.is_file() {
                    return Err(BadInput(format!("{what} {}: no such file", path.display())));
                }
            }
            Some(Tls {
                root_ca: root_ca.clone(),
                cert: cert.clone(),
                key: key.clone(),
            })
        }
        _ => None,
    };
    BridgeSpec::new(
        &args.common.namespace,
        &args.peer_namespace,
        &args.out,
        &args.inbound,
        &args.listen,
        &args.connect,
        tls,
    )
    .map_err(|e| BadInput(format!("bridge: {e}")))
}

// ---------------------------------------------------------------------------------------------
// Out: this host's topics to the peer.

/// A topic sent to the peer, whatever its message type: it wakes the bridge, and its samples
/// leave in publication order ([`send_in_order`]).
trait Out: Outbound<Bytes = ZBytes> {
    fn waker(&self) -> Waker;
}

struct TypedOut<M: Message> {
    subscriber: Subscriber<M>,
    publisher: zenoh::pubsub::Publisher<'static>,
    /// The message's layout, attached to every sample.
    layout: ZBytes,
    /// The newest sample, which the queryable hands a peer that asks (topics with history).
    newest: Option<Arc<Mutex<Option<ZBytes>>>>,
    _queryable: Option<zenoh::query::Queryable<()>>,
    failed_sends: u64,
}

impl<M: Message> Out for TypedOut<M> {
    fn waker(&self) -> Waker {
        self.subscriber.waker()
    }
}

impl<M: Message> Outbound for TypedOut<M> {
    type Bytes = ZBytes;
    fn collect(&mut self, topic: usize, staged: &mut Vec<Staged<ZBytes>>) {
        self.subscriber.drain(|message| {
            staged.push(Staged {
                stamp_ns: message.header().stamp_ns,
                topic,
                // The one copy: the network needs bytes of its own.
                bytes: ZBytes::from(bytemuck::bytes_of(message).to_vec()),
            });
        });
    }
    fn send(&mut self, bytes: ZBytes) {
        if let Some(newest) = &self.newest {
            *newest.lock().unwrap_or_else(|e| e.into_inner()) = Some(bytes.clone());
        }
        if let Err(e) = self
            .publisher
            .put(bytes)
            .attachment(self.layout.clone())
            .wait()
        {
            self.failed_sends += 1;
            if self.failed_sends.is_power_of_two() {
                tracing::warn!(
                    key = self.publisher.key_expr().as_str(),
                    sends = self.failed_sends,
                    "send failed: {e}"
                );
            }
        }
    }
}

fn open_outs(
    ctx: &Context,
    session: &zenoh::Session,
    spec: &BridgeSpec,
) -> Result<Vec<Box<dyn Out>>, Failed> {
    struct Open<'a> {
        ctx: &'a Context,
        session: &'a zenoh::Session,
        spec: &'a BridgeSpec,
        outs: Vec<Box<dyn Out>>,
        error: Option<Failed>,
    }
    impl Open<'_> {
        fn open<M: Message>(&self, topic: Topic<M>) -> Result<Box<dyn Out>, Failed> {
            let key = key_expr(&self.spec.namespace, topic.name);
            let (congestion, priority, express) = qos(delivery(topic.name, self.ctx.mode()));
            let publisher = self
                .session
                .declare_publisher(key.clone())
                .congestion_control(congestion)
                .priority(priority)
                .express(express)
                .wait()?;
            let layout = ZBytes::from(descriptor::<M>());
            let (newest, queryable) = if topic.history > 0 {
                let newest: Arc<Mutex<Option<ZBytes>>> = Arc::default();
                let (held, attached, reply_key) = (newest.clone(), layout.clone(), key.clone());
                let queryable = self
                    .session
                    .declare_queryable(key)
                    .callback(move |query| {
                        let sample = held.lock().unwrap_or_else(|e| e.into_inner()).clone();
                        if let Some(sample) = sample
                            && let Err(e) = query
                                .reply(reply_key.clone(), sample)
                                .attachment(attached.clone())
                                .wait()
                        {
                            tracing::warn!(key = %reply_key, "history reply failed: {e}");
                        }
                    })
                    .wait()?;
                (Some(newest), Some(queryable))
            } else {
                (None, None)
            };
            Ok(Box::new(TypedOut {
                subscriber: self.ctx.subscriber(topic)?,
                publisher,
                layout,
                newest,
                _queryable: queryable,
                failed_sends: 0,
            }))
        }
    }
    impl TopicVisitor for Open<'_> {
        fn visit<M: Message>(&mut self, _constant: &'static str, topic: Topic<M>) {
            if self.error.is_none() && self.spec.out.contains(&topic.name) {
                match self.open(topic) {
                    Ok(out) => self.outs.push(out),
                    Err(e) => self.error = Some(e),
                }
            }
        }
    }
    let mut open = Open {
        ctx,
        session,
        spec,
        outs: Vec::new(),
        error: None,
    };
    topics::for_each(&mut open);
    match open.error {
        Some(e) => Err(e),
        None => Ok(open.outs),
    }
}

/// zenoh's congestion control, priority and express flag for a delivery.
fn qos(delivery: Delivery) -> (CongestionControl, Priority, bool) {
    match delivery {
        Delivery::Reliable { urgent: true } => {
            (CongestionControl::Block, Priority::InteractiveHigh, true)
        }
        Delivery::Reliable { urgent: false } => (CongestionControl::Block, Priority::Data, true),
        Delivery::Newest => (CongestionControl::Drop, Priority::DataLow, false),
    }
}

// ---------------------------------------------------------------------------------------------
// In: the peer's topics, here.

/// What zenoh's threads leave for the bridge's: samples from the peer, in arrival order.
type Inbox = mole_bridge::Inbox<Sample>;

/// A topic from the peer, whatever its message type.
trait In {
    /// Publishes `sample` here if [`Forwarding`] says so; a layout mismatch ends the bridge.
    fn forward(&mut self, sample: &Sample, history: bool) -> Result<(), BadInput>;
    /// Its key on the peer's side, if it keeps history.
    fn history_key(&self) -> Option<&str>;
}

struct TypedIn<M: Message> {
    publisher: Publisher<M>,
    forwarding: Forwarding,
    peer_key: String,
    history: bool,
    _subscriber: zenoh::pubsub::Subscriber<()>,
    malformed: u64,
}

impl<M: Message> In for TypedIn<M> {
    fn forward(&mut self, sample: &Sample, history: bool) -> Result<(), BadInput> {
        let payload = sample.payload().to_bytes();
        let attachment = sample.attachment().map(ZBytes::to_bytes);
        match self
            .forwarding
            .judge(attachment.as_deref(), &payload, history)
        {
            Forward::Publish { lost } => {
                if lost > 0 {
                    self.publisher.count_lost(lost);
                }
                let header: mole_types::Header = bytemuck::pod_read_unaligned(
                    &payload[..core::mem::size_of::<mole_types::Header>()],
                );
                let published = self.publisher.publish(header.tick, header.origin_ns, |m| {
                    bytemuck::bytes_of_mut(m).copy_from_slice(&payload);
                });
                if let Err(e) = published {
                    tracing::warn!(topic = self.publisher.topic(), "{e}");
                }
            }
            Forward::Duplicate | Forward::Stale => {}
            Forward::Malformed { len } => {
                self.publisher.count_invalid();
                self.malformed += 1;
                if self.malformed.is_power_of_two() {
                    tracing::warn!(
                        topic = self.publisher.topic(),
                        len,
                        dropped = self.malformed,
                        "dropped a sample from the peer that is not one whole message"
                    );
                }
            }
            Forward::Mismatch { found } => {
                return Err(BadInput(format!(
                    "cannot open topic `{}` from the peer's bridge ({}): {}",
                    self.publisher.topic(),
                    self.peer_key,
                    layout_mismatch(&mole_runtime::PayloadLayout::of::<M>(), &found)
                )));
            }
        }
        Ok(())
    }
    fn history_key(&self) -> Option<&str> {
        self.history.then_some(self.peer_key.as_str())
    }
}

fn open_ins(
    ctx: &Context,
    session: &zenoh::Session,
    spec: &BridgeSpec,
    inbox: &Arc<Inbox>,
) -> Result<Vec<Box<dyn In>>, Failed> {
    struct Open<'a> {
        ctx: &'a Context,
        session: &'a zenoh::Session,
        spec: &'a BridgeSpec,
        inbox: &'a Arc<Inbox>,
        ins: Vec<Box<dyn In>>,
        error: Option<Failed>,
    }
    impl Open<'_> {
        fn open<M: Message>(&self, topic: Topic<M>) -> Result<Box<dyn In>, Failed> {
            let peer_key = key_expr(&self.spec.peer_namespace, topic.name);
            let newest_only = delivery(topic.name, self.ctx.mode()) == Delivery::Newest;
            let (inbox, index) = (self.inbox.clone(), self.ins.len());
            let subscriber = self
                .session
                .declare_subscriber(peer_key.clone())
                .callback(move |sample| {
                    let entry = Entry {
                        topic: index,
                        item: sample,
                        history: false,
                    };
                    inbox.push(entry, newest_only);
                })
                .wait()?;
            Ok(Box::new(TypedIn {
                publisher: self.ctx.publisher(topic)?,
                forwarding: Forwarding::new::<M>(),
                peer_key,
                history: topic.history > 0,
                _subscriber: subscriber,
                malformed: 0,
            }))
        }
    }
    impl TopicVisitor for Open<'_> {
        fn visit<M: Message>(&mut self, _constant: &'static str, topic: Topic<M>) {
            if self.error.is_none() && self.spec.inbound.contains(&topic.name) {
                match self.open(topic) {
                    Ok(input) => self.ins.push(input),
                    Err(e) => self.error = Some(e),
                }
            }
        }
    }
    let mut open = Open {
        ctx,
        session,
        spec,
        inbox,
        ins: Vec::new(),
        error: None,
    };
    topics::for_each(&mut open);
    match open.error {
        Some(e) => Err(e),
        None => Ok(open.ins),
    }
}

/// Asks the peer for the newest sample of every topic in that keeps history; the replies join
/// the inbox and are forwarded only where they are news.
fn ask_history(session: &zenoh::Session, peer: &str, ins: &[Box<dyn In>], inbox: &Arc<Inbox>) {
    for (index, input) in ins.iter().enumerate() {
        let Some(key) = input.history_key() else {
            continue;
        };
        let inbox = inbox.clone();
        let asked = session
            .get(key)
            .timeout(Duration::from_secs(2))
            .callback(move |reply| {
                if let Ok(sample) = reply.result() {
                    let entry = Entry {
                        topic: index,
                        item: sample.clone(),
                        history: true,
                    };
                    inbox.push(entry, false);
                }
            })
            .wait();
        if let Err(e) = asked {
            tracing::warn!(peer, key, "cannot ask for history: {e}");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The link: is the peer's bridge there?

/// The bridges' liveliness tokens, watched ([`LinkWatch`]): the peer's arrivals and departures
/// are reported, and any other bridge on the link with both namespaces.
struct Link {
    state: Arc<Mutex<LinkWatch>>,
    _watch: zenoh::pubsub::Subscriber<()>,
}

impl Link {
    fn watch(session: &zenoh::Session, spec: &BridgeSpec, ringer: &Ringer) -> Result<Link, Failed> {
        let state = Arc::new(Mutex::new(LinkWatch::new(
            &spec.namespace,
            &spec.peer_namespace,
        )));
        let (seen, ringer, peer) = (state.clone(), ringer.clone(), spec.peer_namespace.clone());
        let watch = session
            .liveliness()
            .declare_subscriber(every_link_token())
            .history(true)
            .callback(move |sample| {
                let mut state = seen.lock().unwrap_or_else(|e| e.into_inner());
                let alive = sample.kind() == SampleKind::Put;
                match state.saw(sample.key_expr().as_str(), alive) {
                    LinkChange::Up => tracing::info!(peer, "link up: the peer's bridge is there"),
                    LinkChange::Down { losses } => tracing::warn!(
                        peer,
                        losses,
                        "link down: the peer's bridge is gone; its topics stop here until it is back"
                    ),
                    LinkChange::Stranger(stranger) => {
                        tracing::warn!("{}", state.stranger_warning(&stranger));
                    }
                    LinkChange::Nothing => {}
                }
                drop(state);
                ringer.ring();
            })
            .wait()?;
        Ok(Link {
            state,
            _watch: watch,
        })
    }

    fn state(&self) -> std::sync::MutexGuard<'_, LinkWatch> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// This bridge's own token's key.
    fn own_key(&self) -> String {
        self.state().own().key()
    }

    /// Waits until the peer's bridge is there; false on a shutdown, an error (the launch
    /// files' namespaces or endpoints do not meet: exit 2) saying what is on the link if the
    /// peer is not there within [`PEER_TIMEOUT`].
    fn wait_for_peer(&self, ctx: &Context, spec: &BridgeSpec) -> Result<bool, BadInput> {
        let started = Instant::now();
        let mut said = Instant::now();
        while !self.state().is_up() {
            if ctx.shutdown_requested() {
                return Ok(false);
            }
            if started.elapsed() > PEER_TIMEOUT {
                return Err(BadInput(self.state().gave_up(&spec.whereabouts())));
            }
            if said.elapsed() > Duration::from_secs(5) {
                tracing::info!("still waiting for the peer's bridge");
                said = Instant::now();
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        self.came_back();
        Ok(true)
    }

    /// Whether the peer came back since the last call.
    fn came_back(&self) -> bool {
        self.state().came_back()
    }
}
