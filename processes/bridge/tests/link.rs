//! The bridge's link, with real `mole-bridge` processes on loopback: a topic crosses between two
//! bridges over mutual TLS, a peer whose certificate another authority signed is refused, a
//! peer speaking another layout of a topic stops the bridge with the runtime's sentence, and a
//! host that joins late gets the map from the other side's history.

use mole_bridge::{descriptor, key_expr};
use mole_integration_tests::{
    TempDir, join_realtime_stack, left_behind, made_by, serial, shm_files, stop_and_clean,
    unique_namespace,
};
use mole_runtime::{PayloadLayout, Publisher, Subscriber};
use mole_types::{Goal, Message, topics};
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

/// A TCP port nobody listens on now.
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

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
        let mut params =
            CertificateParams::new(vec!["127.0.0.1".to_owned(), "localhost".to_owned()])
                .expect("host parameters");
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
}

impl Bridge {
    /// Starts `mole-bridge` in `namespace` with `args` (besides the namespace and clock mode),
    /// its output in `<dir>/<name>.log`.
    fn start(dir: &Path, name: &str, namespace: &str, args: &[String]) -> Bridge {
        let log = dir.join(format!("{name}.log"));
        let out = std::fs::File::create(&log).expect("the bridge's log");
        let child = Command::new(env!("CARGO_BIN_EXE_mole-bridge"))
            .args(["--namespace", namespace, "--mode", "realtime"])
            .args(args)
            .env(mole_types::env::NAMESPACE, namespace)
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
        }
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
    let config = serde_json::json!({
        "mode": "peer",
        "listen": { "endpoints": [] },
        "connect": { "endpoints": [endpoint] },
        "scouting": { "multicast": { "enabled": false }, "gossip": { "enabled": false } },
    });
    let config = zenoh::Config::from_json5(&config.to_string()).expect("zenoh configuration");
    zenoh::open(config)
        .wait()
        .expect("open the test's zenoh session")
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
    let endpoint = format!("tls/127.0.0.1:{}", free_port());

    let mut a_args = bridge_flags(&b_ns, &["--out", "operator/goal", "--listen", &endpoint]);
    a_args.extend(tls_flags(&authority.cert, &a_id));
    let mut a = Bridge::start(&dir.0, "a", &a_ns, &a_args);
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

/// A bridge whose certificate another authority signed (though it trusts the right one, whose
/// certificate is no secret) is turned away by the listener: neither side ever sees the link,
/// and the goals it would carry never arrive.
#[test]
fn a_peer_with_a_wrong_certificate_is_refused() {
    let _serial = serial();
    let before = shm_files();
    let dir = TempDir::new("link-rogue");
    let authority = Authority::new(&dir.0, "mole-ca");
    let other = Authority::new(&dir.0, "other-ca");
    let (a_id, rogue_id) = (authority.sign(&dir.0, "a"), other.sign(&dir.0, "rogue"));
    let (a_ns, rogue_ns) = (unique_namespace("cert-a"), unique_namespace("cert-rogue"));
    let endpoint = format!("tls/127.0.0.1:{}", free_port());

    let mut a_args = bridge_flags(&rogue_ns, &["--in", "operator/goal", "--listen", &endpoint]);
    a_args.extend(tls_flags(&authority.cert, &a_id));
    let mut a = Bridge::start(&dir.0, "a", &a_ns, &a_args);
    a.wait_for("waiting for the peer's bridge");
    let mut rogue_args = bridge_flags(&a_ns, &["--out", "operator/goal", "--connect", &endpoint]);
    rogue_args.extend(tls_flags(&authority.cert, &rogue_id));
    let rogue = Bridge::start(&dir.0, "rogue", &rogue_ns, &rogue_args);

    let planner = join_realtime_stack(&a_ns, "test-planner");
    let mut goals = planner
        .passive_subscriber(topics::OPERATOR_GOAL)
        .expect("goal subscriber");
    let intruder = join_realtime_stack(&rogue_ns, "test-intruder");
    let mut goal = intruder
        .publisher(topics::OPERATOR_GOAL)
        .expect("goal publisher");
    // The rogue tries again and again; three refused handshakes, goals sent all along.
    let refusals = || a.log().matches(REFUSED).count();
    let deadline = Instant::now() + PATIENCE;
    while refusals() < 3 {
        publish_goal(&mut goal, 9.0, 9.0);
        for (name, bridge) in [("the listener", &a), ("the rogue", &rogue)] {
            assert!(
                !bridge.log().contains(LINK_UP),
                "{name} saw the link with a certificate of another authority:\n{}",
                bridge.log()
            );
        }
        assert_eq!(goals.drain(|_| {}), 0, "a goal from the rogue arrived");
        assert!(
            Instant::now() < deadline,
            "the listener never refused the rogue three times:\n{}\n---\n{}",
            a.log(),
            rogue.log()
        );
        std::thread::sleep(Duration::from_millis(50));
    }

    let pids = [a.pid, rogue.pid];
    drop((goals, goal, planner, intruder, a, rogue));
    assert_eq!(ours_left_behind(&before, &pids), Vec::<String>::new());
}

/// What the listener logs (zenoh's warning, rustls' words) when it turns away a certificate
/// that no authority it trusts signed.
const REFUSED: &str = "invalid peer certificate: UnknownIssuer";

/// A peer whose `operator/goal` has another layout (its Goal grew a field) stops the bridge
/// with exit code 2 and the sentence two processes on one machine get: the topic, and that
/// the two disagree on the message layout.
#[test]
fn another_layout_from_the_peer_is_refused_with_the_local_error() {
    let _serial = serial();
    let before = shm_files();
    let dir = TempDir::new("link-layout");
    let (ns, peer) = (unique_namespace("layout"), unique_namespace("layout-peer"));
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let args = bridge_flags(&peer, &["--in", "operator/goal", "--listen", &endpoint]);
    let mut bridge = Bridge::start(&dir.0, "bridge", &ns, &args);
    bridge.wait_for("waiting for the peer's bridge");

    let session = stand_in_peer(&endpoint);
    let _token = session
        .liveliness()
        .declare_token(key_expr(&peer, "bridge"))
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
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());

    let world = join_realtime_stack(&a_ns, "test-world");
    let mut map = world.publisher(topics::WORLD_MAP).expect("map publisher");
    map.publish(0, mole_runtime::now_ns(), |m| {
        m.seed = 4242;
        (m.arena_width, m.arena_height) = (12.5, 8.0);
        (m.dt, m.grid_resolution, m.robot.radius) = (0.01, 0.1, 0.2);
    })
    .expect("publish the map");
    let a_args = bridge_flags(&b_ns, &["--out", "world/map", "--listen", &endpoint]);
    let mut a = Bridge::start(&dir.0, "a", &a_ns, &a_args);
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
        .declare_token(key_expr(&b_ns, "bridge"))
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
