//! The bridge's link, with real `mole-bridge` processes on loopback: a topic crosses between two
//! bridges over mutual TLS; a handshake is refused whichever side's certificate is wrong (signed
//! by another authority, missing, or naming another host); samples leave in publication order;
//! a peer speaking another layout of a topic stops the bridge with the runtime's sentence; and a
//! host that joins late gets the map from the other side's history. Every listener binds port 0
//! and the test reads the port it got from the bridge's report.

use mole_bridge::{LISTENING, LinkToken, descriptor, key_expr};
use mole_integration_tests::{
    TempDir, bridge_listening, join_realtime_stack, left_behind, made_by, serial, shm_files,
    stop_and_clean, unique_namespace,
};
use mole_runtime::{PayloadLayout, Publisher, Subscriber};
use mole_types::{Goal, Header, Message, topics};
use rcgen::{BasicConstraints, CertificateParams, DnType, IsCa, Issuer, KeyPair};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use zenoh::Wait;

/// Against hanging only: how long a bridge may take to come up, link or answer.
const PATIENCE: Duration = Duration::from_secs(30);

/// What a bridge logs when it sees its peer's bridge.
const LINK_UP: &str = "link up";

/// Where a listening bridge of the tests listens: any port the system gives.
const ANY_PORT: &str = "127.0.0.1:0";

/// A certificate authority of the test's own, its certificate a PEM file in the test's directory.
struct Authority {
    cert: PathBuf,
    issuer: Issuer<'static, KeyPair>,
}

/// A host's certificate and private key (PEM files), naming 127.0.0.1 and localhost.
struct Identity {
    cert: PathBuf,
    key: PathBuf,
}

impl Authority {
    /// A new authority named `name`.
    fn new(dir: &Path, name: &str) -> Authority {
        let mut params = CertificateParams::new(Vec::<String>::new()).expect("CA parameters");
        params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        params.distinguished_name.push(DnType::CommonName, name);
        let key = KeyPair::generate().expect("CA key");
        let cert = params.self_signed(&key).expect("CA certificate");
        let path = dir.join(format!("{name}.pem"));
        std::fs::write(&path, cert.pem()).expect("write the CA certificate");
        Authority {
            cert: path,
            issuer: Issuer::new(params, key),
        }
    }

    /// A certificate for the host `name` on loopback, signed by this authority.
    fn sign(&self, dir: &Path, name: &str) -> Identity {
        self.sign_for(dir, name, &["127.0.0.1", "localhost"])
    }

    /// A certificate for the host `name` that names `hosts`, signed by this authority.
    fn sign_for(&self, dir: &Path, name: &str, hosts: &[&str]) -> Identity {
        let hosts = hosts.iter().map(|h| (*h).to_owned()).collect::<Vec<_>>();
        let mut params = CertificateParams::new(hosts).expect("host parameters");
        params.distinguished_name.push(DnType::CommonName, name);
        let key = KeyPair::generate().expect("host key");
        let cert = params
            .signed_by(&key, &self.issuer)
            .expect("host certificate");
        let identity = Identity {
            cert: dir.join(format!("{name}.pem")),
            key: dir.join(format!("{name}.key")),
        };
        std::fs::write(&identity.cert, cert.pem()).expect("write the host certificate");
        std::fs::write(&identity.key, key.serialize_pem()).expect("write the host key");
        identity
    }
}

/// The TLS flags of a bridge that trusts `root_ca` and shows `identity`.
fn tls_flags(root_ca: &Path, identity: &Identity) -> Vec<String> {
    [
        ("--tls-root-ca", root_ca),
        ("--tls-cert", identity.cert.as_path()),
        ("--tls-key", identity.key.as_path()),
    ]
    .into_iter()
    .flat_map(|(flag, path)| [flag.to_owned(), path.display().to_string()])
    .collect()
}

/// A bridge's flags: its peer's namespace, then `rest`.
fn bridge_flags(peer: &str, rest: &[&str]) -> Vec<String> {
    ["--peer-namespace", peer]
        .iter()
        .chain(rest)
        .map(|s| (*s).to_owned())
        .collect()
}

/// A running `mole-bridge`, its stdout and stderr in a file; stopped with Ctrl-C (killed if it
/// hangs, and what it left in shared memory swept) and waited for however the test ends.
struct Bridge {
    child: Option<Child>,
    pid: u32,
    namespace: String,
    log: PathBuf,
    /// Its output directory, where it says where it listens.
    out: PathBuf,
}

impl Bridge {
    /// Starts `mole-bridge` in `namespace` with `args` (besides the namespace and clock mode),
    /// its output in `<dir>/<name>.log`, its output directory `<dir>/<name>`.
    fn start(dir: &Path, name: &str, namespace: &str, args: &[String]) -> Bridge {
        let log = dir.join(format!("{name}.log"));
        let out_dir = dir.join(name);
        std::fs::create_dir_all(&out_dir).expect("the bridge's output directory");
        let out = std::fs::File::create(&log).expect("the bridge's log");
        let child = Command::new(env!("CARGO_BIN_EXE_mole-bridge"))
            .args(["--namespace", namespace, "--mode", "realtime"])
            .args(args)
            .env(mole_types::env::NAMESPACE, namespace)
            .env(mole_types::env::OUT, &out_dir)
            .env("NO_COLOR", "1")
            .env_remove("RUST_LOG")
            .stdin(Stdio::null())
            .stdout(out.try_clone().expect("the log for stdout"))
            .stderr(out)
            .spawn()
            .expect("start mole-bridge");
        Bridge {
            pid: child.id(),
            child: Some(child),
            namespace: namespace.to_owned(),
            log,
            out: out_dir,
        }
    }

    /// The endpoint it listens on, the port zenoh bound, as it reports it (in its output
    /// directory, and the same in its log).
    fn listening(&mut self) -> String {
        let endpoint = bridge_listening(&self.out, PATIENCE).unwrap_or_else(|| {
            panic!(
                "{} never said where it listens:\n{}",
                self.log.display(),
                self.log()
            )
        });
        assert!(!endpoint.ends_with(":0"), "{endpoint}");
        self.wait_for(&format!("{LISTENING} {endpoint}"));
        endpoint
    }

    /// Everything the bridge wrote so far.
    fn log(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }

    /// Waits until the bridge wrote `needle`; fails if it exits first.
    fn wait_for(&mut self, needle: &str) {
        let deadline = Instant::now() + PATIENCE;
        while !self.log().contains(needle) {
            let exited = self
                .child
                .as_mut()
                .and_then(|c| c.try_wait().ok().flatten());
            assert!(
                exited.is_none() && Instant::now() < deadline,
                "{} never said `{needle}` (exit: {exited:?}):\n{}",
                self.log.display(),
                self.log()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Waits for the bridge to exit on its own, doing `meanwhile` between looks.
    fn wait_for_exit(&mut self, mut meanwhile: impl FnMut()) -> ExitStatus {
        let child = self.child.as_mut().expect("running");
        let deadline = Instant::now() + PATIENCE;
        loop {
            if let Some(status) = child.try_wait().expect("the bridge's status") {
                return status;
            }
            assert!(
                Instant::now() < deadline,
                "the bridge did not stop:\n{}",
                self.log()
            );
            meanwhile();
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl Drop for Bridge {
    fn drop(&mut self) {
        stop_and_clean(self.child.take(), &self.namespace);
        // Killed after Ctrl-C did not stop it: what it left is swept (it is dead now).
        if !made_by(&shm_files(), &BTreeSet::from([self.pid])).is_empty() {
            mole_runtime::cleanup_dead_nodes();
        }
    }
}

/// A zenoh session of the test's own standing in for a peer's bridge: a peer that connects to
/// `endpoint` and finds nobody by multicast.
fn stand_in_peer(endpoint: &str) -> zenoh::Session {
    open_stand_in(stand_in_config(endpoint))
}

/// The stand-in's configuration: a peer that connects to `endpoint` (trying again in the
/// background until it can) and finds nobody by multicast.
fn stand_in_config(endpoint: &str) -> serde_json::Value {
    serde_json::json!({
        "mode": "peer",
        "listen": { "endpoints": [] },
        "connect": {
            "endpoints": [endpoint],
            "timeout_ms": -1,
            "exit_on_failure": false,
            "retry": { "period_init_ms": 100, "period_max_ms": 500, "period_increase_factor": 2 },
        },
        "scouting": { "multicast": { "enabled": false }, "gossip": { "enabled": false } },
    })
}

fn open_stand_in(config: serde_json::Value) -> zenoh::Session {
    let config = zenoh::Config::from_json5(&config.to_string()).expect("zenoh configuration");
    zenoh::open(config)
        .wait()
        .expect("open the test's zenoh session")
}

/// The liveliness token the bridge of `peer` holds, the bridge of `namespace` expecting it.
fn token_of(namespace: &str, peer: &str) -> String {
    LinkToken {
        namespace: namespace.to_owned(),
        peer: peer.to_owned(),
    }
    .key()
}

/// Reads `subscriber` until a message comes; fails naming `what` if none comes (the bridges'
/// logs in the message).
fn first<M: Message>(subscriber: &mut Subscriber<M>, what: &str, bridges: &[&Bridge]) -> M {
    let deadline = Instant::now() + PATIENCE;
    loop {
        let mut got = None;
        subscriber.drain(|m| got = Some(*m));
        if let Some(message) = got {
            return message;
        }
        assert!(
            Instant::now() < deadline,
            "{what}: nothing came\n{}",
            bridges
                .iter()
                .map(|b| b.log())
                .collect::<Vec<_>>()
                .join("\n---\n")
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Publishes a goal at (`x`, `y`).
fn publish_goal(publisher: &mut Publisher<Goal>, x: f64, y: f64) {
    publisher
        .publish(0, mole_runtime::now_ns(), |goal| {
            goal.x = x;
            goal.y = y;
            goal.tolerance = 0.0;
        })
        .expect("publish a goal");
}

/// The shared memory the test's own process and its bridges left behind (other stacks on the
/// machine come and go as they like).
fn ours_left_behind(before: &[String], bridges: &[u32]) -> Vec<String> {
    let mut pids: BTreeSet<u32> = bridges.iter().copied().collect();
    pids.insert(std::process::id());
    made_by(&left_behind(before), &pids)
}

/// A goal published in A's namespace comes out in B's, carried by two bridges that checked each
/// other's certificate (mutual TLS, both signed by the test's authority).
#[test]
fn a_topic_crosses_between_two_bridges_over_tls() {
    let _serial = serial();
    let before = shm_files();
    let dir = TempDir::new("link-tls");
    let authority = Authority::new(&dir.0, "mole-ca");
    let (a_id, b_id) = (authority.sign(&dir.0, "a"), authority.sign(&dir.0, "b"));
    let (a_ns, b_ns) = (unique_namespace("tls-a"), unique_namespace("tls-b"));
    let listen = format!("tls/{ANY_PORT}");

    let mut a_args = bridge_flags(&b_ns, &["--out", "operator/goal", "--listen", &listen]);
    a_args.extend(tls_flags(&authority.cert, &a_id));
    let mut a = Bridge::start(&dir.0, "a", &a_ns, &a_args);
    let endpoint = a.listening();
    let mut b_args = bridge_flags(&a_ns, &["--in", "operator/goal", "--connect", &endpoint]);
    b_args.extend(tls_flags(&authority.cert, &b_id));
    let mut b = Bridge::start(&dir.0, "b", &b_ns, &b_args);
    a.wait_for(LINK_UP);
    b.wait_for(LINK_UP);

    let operator = join_realtime_stack(&a_ns, "test-operator");
    let mut goal = operator
        .publisher(topics::OPERATOR_GOAL)
        .expect("goal publisher");
    let planner = join_realtime_stack(&b_ns, "test-planner");
    let mut goals = planner
        .passive_subscriber(topics::OPERATOR_GOAL)
        .expect("goal subscriber");
    publish_goal(&mut goal, 3.25, -1.5);
    let arrived = first(&mut goals, "the goal across the link", &[&a, &b]);
    assert_eq!((arrived.x, arrived.y), (3.25, -1.5));

    let pids = [a.pid, b.pid];
    drop((goals, goal, planner, operator, a, b));
    assert_eq!(ours_left_behind(&before, &pids), Vec::<String>::new());
}

/// How a refused handshake shows: until the listener's log says `needle` (the reason, in
/// rustls' words) three times, while `send` publishes goals on the refused side all along,
/// neither side sees the link (`saw_link` asks each, by name) and no goal reaches `goals`.
fn assert_refused(
    listener: &Bridge,
    needle: &str,
    saw_link: &[(&str, &dyn Fn() -> bool)],
    mut send: impl FnMut(),
    goals: &mut Subscriber<Goal>,
    logs: &dyn Fn() -> String,
) {
    let refusals = || listener.log().matches(needle).count();
    let deadline = Instant::now() + PATIENCE;
    while refusals() < 3 {
        send();
        for (name, saw) in saw_link {
            assert!(!saw(), "{name} saw the link come up:\n{}", logs());
        }
        assert_eq!(goals.drain(|_| {}), 0, "a goal crossed:\n{}", logs());
        assert!(
            Instant::now() < deadline,
            "the handshake was never refused with `{needle}` three times:\n{}",
            logs()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Two bridges, the listener `a` and the connector `b`, the goals going from the listener to the
/// connector if `a_sends`, and the other way otherwise: the handshake is refused with
/// `needle` in the listener's log, neither sees the link and no goal crosses.
fn two_bridges_refused(
    test: &str,
    a_identity: impl FnOnce(&Path, &Authority) -> Identity,
    b_identity: impl FnOnce(&Path, &Authority) -> Identity,
    a_sends: bool,
    needle: &str,
) {
    let _serial = serial();
    let before = shm_files();
    let dir = TempDir::new(test);
    let authority = Authority::new(&dir.0, "mole-ca");
    let (a_id, b_id) = (
        a_identity(&dir.0, &authority),
        b_identity(&dir.0, &authority),
    );
    let (a_ns, b_ns) = (
        unique_namespace(&format!("{test}-a")),
        unique_namespace(&format!("{test}-b")),
    );
    let (a_goal, b_goal) = if a_sends {
        ("--out", "--in")
    } else {
        ("--in", "--out")
    };
    let listen = format!("tls/{ANY_PORT}");
    let mut a_args = bridge_flags(&b_ns, &[a_goal, "operator/goal", "--listen", &listen]);
    a_args.extend(tls_flags(&authority.cert, &a_id));
    let mut a = Bridge::start(&dir.0, "a", &a_ns, &a_args);
    let endpoint = a.listening();
    let mut b_args = bridge_flags(&a_ns, &[b_goal, "operator/goal", "--connect", &endpoint]);
    b_args.extend(tls_flags(&authority.cert, &b_id));
    let b = Bridge::start(&dir.0, "b", &b_ns, &b_args);

    let (from, to) = if a_sends {
        (&a_ns, &b_ns)
    } else {
        (&b_ns, &a_ns)
    };
    let receiver = join_realtime_stack(to, "test-planner");
    let mut goals = receiver
        .passive_subscriber(topics::OPERATOR_GOAL)
        .expect("goal subscriber");
    let sender = join_realtime_stack(from, "test-operator");
    let mut goal = sender
        .publisher(topics::OPERATOR_GOAL)
        .expect("goal publisher");
    let logs = || format!("{}\n---\n{}", a.log(), b.log());
    assert_refused(
        &a,
        needle,
        &[
            ("the listener", &|| a.log().contains(LINK_UP)),
            ("the connector", &|| b.log().contains(LINK_UP)),
        ],
        || publish_goal(&mut goal, 9.0, 9.0),
        &mut goals,
        &logs,
    );

    let pids = [a.pid, b.pid];
    drop((goals, goal, receiver, sender, a, b));
    assert_eq!(ours_left_behind(&before, &pids), Vec::<String>::new());
}

/// A bridge whose certificate another authority signed (though it trusts the right one, whose
/// certificate is no secret) is turned away by the listener: neither side ever sees the link,
/// and the goals it would carry never arrive.
#[test]
fn a_peer_with_a_wrong_certificate_is_refused() {
    two_bridges_refused(
        "link-rogue",
        |dir, authority| authority.sign(dir, "a"),
        |dir, _| Authority::new(dir, "other-ca").sign(dir, "rogue"),
        false,
        "invalid peer certificate: UnknownIssuer",
    );
}

/// The other way round: a listener whose certificate another authority signed is turned away
/// by the connecting bridge, which sends it the alert "unknown CA"; nothing reaches the
/// connector.
#[test]
fn the_connector_refuses_a_listener_another_authority_signed() {
    two_bridges_refused(
        "link-rogue-listener",
        |dir, _| Authority::new(dir, "other-ca").sign(dir, "rogue"),
        |dir, authority| authority.sign(dir, "b"),
        true,
        "received fatal alert: UnknownCA",
    );
}

/// A listener whose certificate the right authority signed, but for another host, is turned
/// away by the connecting bridge, which checks the name it connects to (127.0.0.1) and sends the
/// alert "bad certificate"; nothing reaches the connector.
#[test]
fn the_connector_refuses_a_listener_named_for_another_host() {
    two_bridges_refused(
        "link-misnamed",
        |dir, authority| authority.sign_for(dir, "a", &["robot.example"]),
        |dir, authority| authority.sign(dir, "b"),
        true,
        "received fatal alert: BadCertificate",
    );
}

/// A peer that shows no certificate at all (it trusts the right authority, holds the expected
/// liveliness token and sends goals with the right layout) is turned away by the listener:
/// neither side sees the other's token and no goal arrives.
#[test]
fn a_peer_without_a_certificate_is_refused() {
    let _serial = serial();
    let before = shm_files();
    let dir = TempDir::new("link-anonymous");
    let authority = Authority::new(&dir.0, "mole-ca");
    let a_id = authority.sign(&dir.0, "a");
    let (a_ns, peer_ns) = (unique_namespace("anon-a"), unique_namespace("anon-peer"));
    let listen = format!("tls/{ANY_PORT}");
    let mut a_args = bridge_flags(&peer_ns, &["--in", "operator/goal", "--listen", &listen]);
    a_args.extend(tls_flags(&authority.cert, &a_id));
    let mut a = Bridge::start(&dir.0, "a", &a_ns, &a_args);
    let endpoint = a.listening();

    let mut config = stand_in_config(&endpoint);
    config["transport"] = serde_json::json!({ "link": { "tls": {
        "root_ca_certificate": authority.cert.display().to_string(),
    }}});
    let anonymous = open_stand_in(config);
    let _token = anonymous
        .liveliness()
        .declare_token(token_of(&peer_ns, &a_ns))
        .wait()
        .expect("the stand-in's liveliness token");
    let (seen, tokens) = mpsc::channel();
    let _watch = anonymous
        .liveliness()
        .declare_subscriber(token_of(&a_ns, &peer_ns))
        .history(true)
        .callback(move |sample| {
            let _ = seen.send(sample.key_expr().to_string());
        })
        .wait()
        .expect("the stand-in's liveliness watch");
    let planner = join_realtime_stack(&a_ns, "test-planner");
    let mut goals = planner
        .passive_subscriber(topics::OPERATOR_GOAL)
        .expect("goal subscriber");
    let key = key_expr(&peer_ns, topics::OPERATOR_GOAL.name);
    let goal = Goal {
        header: Header::default(),
        x: 9.0,
        y: 9.0,
        tolerance: 0.0,
    };
    assert_refused(
        &a,
        "peer sent no certificates",
        &[
            ("the listener", &|| a.log().contains(LINK_UP)),
            ("the peer without a certificate", &|| {
                tokens.try_recv().is_ok()
            }),
        ],
        || {
            anonymous
                .put(&key, bytemuck::bytes_of(&goal).to_vec())
                .attachment(descriptor::<Goal>())
                .wait()
                .expect("put a goal");
        },
        &mut goals,
        &|| a.log(),
    );

    let pids = [a.pid];
    drop((goals, planner, _watch, _token, anonymous, a));
    assert_eq!(ours_left_behind(&before, &pids), Vec::<String>::new());
}

/// Samples leave in the order they were published, across topics, not topic by topic: a
/// backlog of odometry and tactile readings published alternately (a step's tactile reading,
/// then its odometry, which wakes localization on the far side) while the peer was not there
/// reaches the peer alternately once it comes, and so does a reading published after.
#[test]
fn samples_leave_in_publication_order() {
    let _serial = serial();
    let before = shm_files();
    let dir = TempDir::new("link-order");
    let (ns, peer) = (unique_namespace("order"), unique_namespace("order-peer"));
    let listen = format!("tcp/{ANY_PORT}");
    let args = bridge_flags(
        &peer,
        &[
            "--out",
            "sensing/tactile",
            "--out",
            "sensing/odom",
            "--listen",
            &listen,
        ],
    );
    let mut bridge = Bridge::start(&dir.0, "bridge", &ns, &args);
    let endpoint = bridge.listening();
    bridge.wait_for("waiting for the peer's bridge");

    let sensing = join_realtime_stack(&ns, "test-sensing");
    let mut tactile = sensing
        .publisher(topics::SENSING_TACTILE)
        .expect("tactile publisher");
    let mut odom = sensing
        .publisher(topics::SENSING_ODOM)
        .expect("odometry publisher");
    let mut published = Vec::new();
    let mut step = |tick: u64, published: &mut Vec<(&str, u64)>| {
        tactile
            .publish(tick, mole_runtime::now_ns(), |_| {})
            .expect("publish tactile");
        published.push((topics::SENSING_TACTILE.name, tick));
        odom.publish(tick, mole_runtime::now_ns(), |_| {})
            .expect("publish odometry");
        published.push((topics::SENSING_ODOM.name, tick));
    };
    for tick in 1..=3 {
        step(tick, &mut published);
    }

    // The peer comes: what it receives, in the order it arrives.
    let peer_session = stand_in_peer(&endpoint);
    let (sent, arrived) = mpsc::channel();
    let _readings = peer_session
        .declare_subscriber(key_expr(&ns, "sensing/*"))
        .callback(move |sample| {
            let header: Header =
                bytemuck::pod_read_unaligned(&sample.payload().to_bytes()[..size_of::<Header>()]);
            let topic = sample
                .key_expr()
                .as_str()
                .rsplit_once("/sensing/")
                .map(|(_, t)| format!("sensing/{t}"))
                .unwrap_or_default();
            let _ = sent.send((topic, header.tick, header.seq));
        })
        .wait()
        .expect("the stand-in's subscriber");
    let _token = peer_session
        .liveliness()
        .declare_token(token_of(&peer, &ns))
        .wait()
        .expect("the stand-in's liveliness token");
    bridge.wait_for(LINK_UP);
    step(4, &mut published);

    let mut received = Vec::new();
    while received.len() < published.len() {
        let next = arrived.recv_timeout(PATIENCE).unwrap_or_else(|_| {
            panic!(
                "only {} of {} readings arrived: {received:?}\n{}",
                received.len(),
                published.len(),
                bridge.log()
            )
        });
        received.push(next);
    }
    // Across topics: the order they were published in (topic, step). Each topic's own
    // sequence numbers: 0, 1, 2, 3, none lost or repeated.
    let order: Vec<(&str, u64)> = received
        .iter()
        .map(|(t, tick, _)| (t.as_str(), *tick))
        .collect();
    assert_eq!(order, published, "not in publication order");
    for topic in [topics::SENSING_TACTILE.name, topics::SENSING_ODOM.name] {
        let seqs: Vec<u64> = received
            .iter()
            .filter(|(t, ..)| t == topic)
            .map(|r| r.2)
            .collect();
        assert_eq!(seqs, [0, 1, 2, 3], "{topic}: sequence numbers");
    }

    let pids = [bridge.pid];
    drop((
        _readings,
        _token,
        peer_session,
        odom,
        tactile,
        sensing,
        bridge,
    ));
    assert_eq!(ours_left_behind(&before, &pids), Vec::<String>::new());
}

/// A peer whose `operator/goal` has another layout (its Goal grew a field) stops the bridge
/// with exit code 2 and the sentence two processes on one machine get: the topic, and that
/// the two disagree on the message layout.
#[test]
fn another_layout_from_the_peer_is_refused_with_the_local_error() {
    let _serial = serial();
    let before = shm_files();
    let dir = TempDir::new("link-layout");
    let (ns, peer) = (unique_namespace("layout"), unique_namespace("layout-peer"));
    let listen = format!("tcp/{ANY_PORT}");
    let args = bridge_flags(&peer, &["--in", "operator/goal", "--listen", &listen]);
    let mut bridge = Bridge::start(&dir.0, "bridge", &ns, &args);
    let endpoint = bridge.listening();
    bridge.wait_for("waiting for the peer's bridge");

    let session = stand_in_peer(&endpoint);
    let _token = session
        .liveliness()
        .declare_token(token_of(&peer, &ns))
        .wait()
        .expect("the stand-in's liveliness token");
    let grown = PayloadLayout {
        size: size_of::<Goal>() + 8,
        ..PayloadLayout::of::<Goal>()
    }
    .to_string();
    let key = key_expr(&peer, topics::OPERATOR_GOAL.name);
    let status = bridge.wait_for_exit(|| {
        session
            .put(&key, vec![0u8; size_of::<Goal>()])
            .attachment(grown.clone())
            .wait()
            .expect("put a goal of another layout");
    });

    let log = bridge.log();
    assert_eq!(status.code(), Some(2), "{log}");
    for needle in [
        "cannot open topic `operator/goal`",
        "disagree on the message layout",
        &grown,
        &descriptor::<Goal>(),
    ] {
        assert!(log.contains(needle), "no `{needle}` in:\n{log}");
    }
    let pids = [bridge.pid];
    drop((session, bridge));
    assert_eq!(ours_left_behind(&before, &pids), Vec::<String>::new());
}

/// A map published once, long before the other host's bridge starts, still reaches it: the
/// bridge sent its one live copy to an earlier peer (the test, standing in), and the late
/// bridge gets it by asking the history of the topic.
#[test]
fn a_late_host_gets_the_map_from_history() {
    let _serial = serial();
    let before = shm_files();
    let dir = TempDir::new("link-late");
    let (a_ns, b_ns) = (unique_namespace("late-a"), unique_namespace("late-b"));
    let listen = format!("tcp/{ANY_PORT}");

    let world = join_realtime_stack(&a_ns, "test-world");
    let mut map = world.publisher(topics::WORLD_MAP).expect("map publisher");
    map.publish(0, mole_runtime::now_ns(), |m| {
        m.seed = 4242;
        (m.arena_width, m.arena_height) = (12.5, 8.0);
        (m.dt, m.grid_resolution, m.robot.radius) = (0.01, 0.1, 0.2);
    })
    .expect("publish the map");
    let a_args = bridge_flags(&b_ns, &["--out", "world/map", "--listen", &listen]);
    let mut a = Bridge::start(&dir.0, "a", &a_ns, &a_args);
    let endpoint = a.listening();
    a.wait_for("waiting for the peer's bridge");

    // An earlier peer takes the map's one live copy, then goes.
    let early = stand_in_peer(&endpoint);
    let (sent, live) = mpsc::channel();
    let _live = early
        .declare_subscriber(key_expr(&a_ns, topics::WORLD_MAP.name))
        .callback(move |sample| {
            let _ = sent.send(sample.payload().len());
        })
        .wait()
        .expect("the stand-in's map subscriber");
    let token = early
        .liveliness()
        .declare_token(token_of(&b_ns, &a_ns))
        .wait()
        .expect("the stand-in's liveliness token");
    let deadline = Instant::now() + PATIENCE;
    while live.try_recv().is_err() {
        assert!(
            Instant::now() < deadline,
            "the map never went out live:\n{}",
            a.log()
        );
        // Hands the map (history 1) to the bridge's subscriber, which joined after it was sent.
        map.update_connections();
        std::thread::sleep(Duration::from_millis(20));
    }
    drop((token, early));
    a.wait_for("link down");

    let mapping = join_realtime_stack(&b_ns, "test-mapping");
    let mut maps = mapping
        .passive_subscriber(topics::WORLD_MAP)
        .expect("map subscriber");
    let b_args = bridge_flags(&a_ns, &["--in", "world/map", "--connect", &endpoint]);
    let b = Bridge::start(&dir.0, "b", &b_ns, &b_args);
    let late = first(&mut maps, "the map for the late host", &[&a, &b]);
    assert_eq!((late.seed, late.arena_width), (4242, 12.5));

    let pids = [a.pid, b.pid];
    drop((maps, mapping, map, world, a, b));
    assert_eq!(ours_left_behind(&before, &pids), Vec::<String>::new());
}
