//! The live view, as a user meets it: `mole up --view` serves frames over a WebSocket that agree
//! with what the stack publishes, every frame it makes to a page that keeps up, refuses other
//! sites' pages, and survives garbage input, counting it; watch-only, it refuses every input; a
//! port in use is refused, serving beyond loopback is warned of;
//! the page, loaded in headless Chromium, draws the robot moving and the map filling without a
//! console error; and `mole view FILE` shows a recording with no stack and no IPC: its timeline
//! spans the file, a seek shows the recorded truth of its tick, play reaches the end, pause
//! holds, and a file it cannot read is refused before anything is served.

use mole_integration_tests::*;
use mole_types::{Goal, Grid, Truth, WorldMap, topics};
use serde_json::{Value, json};
use std::collections::{BTreeMap, VecDeque};
use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use tungstenite::stream::MaybeTlsStream;
use tungstenite::{Message, WebSocket};

/// How long the browser test watches the page.
const WATCH: Duration = Duration::from_secs(3);
/// Frames a WebSocket test reads in a row (three seconds of them).
const FRAMES_WATCHED: usize = 60;
/// Guards a read that would otherwise hang forever.
const READ_TIMEOUT: Duration = Duration::from_secs(10);
/// Long enough a realtime run that the stack outlives every test (they stop it).
const RUN: &[&str] = &["--mode", "realtime", "--duration", "120", "--view=0"];

type Socket = WebSocket<MaybeTlsStream<TcpStream>>;

/// A WebSocket client on `url` whose reads give up after [`READ_TIMEOUT`].
fn connect(url: &str) -> Socket {
    let (socket, _) = tungstenite::connect(url).unwrap_or_else(|e| panic!("connect {url}: {e}"));
    if let MaybeTlsStream::Plain(stream) = socket.get_ref() {
        stream
            .set_read_timeout(Some(READ_TIMEOUT))
            .expect("read timeout");
    }
    socket
}

/// The next frame the view sent.
fn next_frame(socket: &mut Socket) -> Value {
    loop {
        match socket.read().expect("a frame from the view") {
            Message::Text(text) => return serde_json::from_str(&text).expect("a frame is JSON"),
            Message::Close(close) => panic!("the view closed the connection: {close:?}"),
            _ => {}
        }
    }
}

/// A page's picture of a grid: the whole first, tiles applied after.
#[derive(Default)]
struct PageGrid {
    width: usize,
    tick: u64,
    cells: Vec<u8>,
}

impl PageGrid {
    fn apply(&mut self, update: &Value) {
        use base64::Engine as _;
        let width = update["width"].as_u64().expect("width") as usize;
        let height = update["height"].as_u64().expect("height") as usize;
        if update["whole"] == true {
            *self = PageGrid {
                width,
                tick: 0,
                cells: vec![0; width * height],
            };
        }
        self.tick = update["tick"].as_u64().expect("tick");
        for tile in update["tiles"].as_array().expect("tiles") {
            let at = |k: &str| tile[k].as_u64().expect("tile field") as usize;
            let (x, y, w, h) = (at("x"), at("y"), at("w"), at("h"));
            let cells = base64::engine::general_purpose::STANDARD
                .decode(tile["cells"].as_str().expect("cells"))
                .expect("base64 cells");
            for row in 0..h {
                let start = (y + row) * self.width + x;
                self.cells[start..start + w].copy_from_slice(&cells[row * w..(row + 1) * w]);
            }
        }
    }
}

/// What the test itself reads of the stack: the truth by tick, the newest grids.
struct Witness {
    _ctx: mole_runtime::Context,
    map: mole_runtime::Subscriber<WorldMap>,
    truth: mole_runtime::Subscriber<Truth>,
    grid: mole_runtime::Subscriber<Grid>,
    goal: mole_runtime::Subscriber<Goal>,
    truths: BTreeMap<u64, (f64, f64, f64)>,
    grids: VecDeque<(u64, Vec<u8>)>,
}

impl Witness {
    fn join(namespace: &str) -> Witness {
        let ctx = join_realtime_stack(namespace, "view-witness");
        Witness {
            map: ctx.passive_subscriber(topics::WORLD_MAP).expect("map"),
            truth: ctx.passive_subscriber(topics::WORLD_TRUTH).expect("truth"),
            grid: ctx.passive_subscriber(topics::MAPPING_GRID).expect("grid"),
            goal: ctx.passive_subscriber(topics::OPERATOR_GOAL).expect("goal"),
            _ctx: ctx,
            truths: BTreeMap::new(),
            grids: VecDeque::new(),
        }
    }

    /// Reads what was published since the last look.
    fn look(&mut self) {
        let truths = &mut self.truths;
        self.truth.drain(|t| {
            truths.insert(t.header.tick, (t.x, t.y, t.theta));
        });
        let grids = &mut self.grids;
        self.grid.drain(|g| {
            if grids.len() == 64 {
                grids.pop_front();
            }
            grids.push_back((g.header.tick, g.cells().to_vec()));
        });
        self.map.drain(|_| {});
    }
}

/// A WebSocket handshake to `ws_url` that says it comes from a page of `origin`: the HTTP
/// status it was answered with (101 when the view took it).
fn handshake_from(ws_url: &str, origin: &str) -> u16 {
    use tungstenite::client::IntoClientRequest as _;
    let mut request = ws_url.into_client_request().expect("a request");
    request
        .headers_mut()
        .insert("Origin", origin.parse().expect("an Origin header"));
    match tungstenite::connect(request) {
        Ok((_, response)) => response.status().as_u16(),
        Err(tungstenite::Error::Http(response)) => response.status().as_u16(),
        Err(e) => panic!("the handshake from {origin} broke: {e}"),
    }
}

/// How many times the view of the run in `out` started: its log says `serving the view` once a
/// start (the launcher appends every start's output to logs/view.log).
fn view_starts(out: &std::path::Path) -> usize {
    std::fs::read_to_string(out.join("logs/view.log"))
        .unwrap_or_default()
        .matches("serving the view")
        .count()
}

/// The frames agree with the stack's own topics: the first holds the arena and the whole grid
/// of world/map's and mapping/grid's size; of 60 frames in a row, each the view made next (their
/// `seq` consecutive: a page that keeps up is sent every frame), the truth's tick advances and
/// each frame's true pose is world/truth's at that tick; the page's grid, rebuilt from tiles, is
/// mapping/grid's at its tick; a WebSocket from another origin is refused with 403, one from the
/// page's own is let in; a goal reaches operator/goal; garbage (bad JSON, a NaN goal, a
/// recording's timeline op, a 1 MB message) is refused and counted while the stack goes on and
/// the view does too: the same process, started once.
#[test]
fn websocket_frames_match_the_stack_and_garbage_is_counted() {
    let _serial = serial();
    let mut stack = Stack::start("view-ws", RUN);
    let lines = stack.stdout_lines().expect("stdout");
    let url = view_url(&lines, Duration::from_secs(60));
    let ws_url = format!("{}ws", url.replacen("http://", "ws://", 1));
    let view = pid_of(&stack.namespace, "mole-view").expect("the view runs");
    let mut witness = Witness::join(&stack.namespace);
    // A page that connects before mapping's first grid gets it whole later: connect again.
    let deadline = Instant::now() + READ_TIMEOUT;
    let (mut socket, first) = loop {
        let mut socket = connect(&ws_url);
        let first = next_frame(&mut socket);
        if first["grids"].get("frontier").is_some() || Instant::now() > deadline {
            break (socket, first);
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!(first["type"], "frame");
    assert_eq!(first["full"], true, "{first}");
    witness.look();
    let map = witness.map.latest().expect("world/map from history");
    assert_eq!(first["arena"]["width"], map.arena_width);
    assert_eq!(first["arena"]["height"], map.arena_height);
    assert_eq!(
        first["arena"]["obstacles"].as_array().map(Vec::len),
        Some(map.n_obstacles as usize)
    );
    let mut page = PageGrid::default();
    let update = &first["grids"]["frontier"];
    assert_eq!(update["whole"], true, "{update}");
    page.apply(update);
    let published = witness.grid.latest().expect("mapping/grid");
    assert_eq!(
        (page.width, page.cells.len()),
        (
            published.width as usize,
            (published.width * published.height) as usize
        )
    );

    let first_grid_tick = page.tick;
    let mut poses_checked = 0u32;
    let mut grid_ticks_checked = Vec::new();
    let (mut ticks, mut seqs) = (Vec::new(), vec![first["seq"].as_u64().expect("seq")]);
    while seqs.len() < FRAMES_WATCHED {
        let frame = next_frame(&mut socket);
        seqs.push(frame["seq"].as_u64().expect("seq"));
        assert_eq!(frame["full"], false);
        if let Some(update) = frame["grids"].get("frontier") {
            page.apply(update);
        }
        witness.look();
        let truth = &frame["truth"];
        let tick = truth["tick"].as_u64().expect("truth tick");
        ticks.push(tick);
        if let Some(&(x, y, theta)) = witness.truths.get(&tick) {
            // serde_json writes f64 exactly but reads it back to within an ulp or so.
            let near = |field: &str, published: f64| {
                let sent = truth[field].as_f64().expect("a number");
                assert!(
                    (sent - published).abs() <= 1e-12 * published.abs().max(1.0),
                    "truth {field} at tick {tick}: frame {sent}, world/truth {published}"
                );
            };
            near("x", x);
            near("y", y);
            near("theta", theta);
            poses_checked += 1;
        }
        if let Some((_, cells)) = witness.grids.iter().find(|(t, _)| *t == page.tick) {
            assert!(
                *cells == page.cells,
                "the page's grid at tick {} differs from mapping/grid's",
                page.tick
            );
            grid_ticks_checked.push(page.tick);
        }
    }
    assert!(
        seqs.windows(2).all(|w| w[1] == w[0] + 1),
        "frames skipped: seq {seqs:?}"
    );
    assert!(ticks.windows(2).all(|w| w[0] <= w[1]), "{ticks:?}");
    assert!(
        ticks.last() > ticks.first(),
        "the truth never advanced: {ticks:?}"
    );
    assert!(poses_checked >= 3, "only {poses_checked} poses compared");
    assert!(
        grid_ticks_checked.iter().any(|t| *t > first_grid_tick),
        "no grid updated by tiles was compared (ticks {grid_ticks_checked:?}, first {first_grid_tick})"
    );

    // Another site's page is refused before the WebSocket opens; the view's own page is not.
    let host = url
        .trim_start_matches("http://")
        .trim_end_matches('/')
        .to_string();
    assert_eq!(handshake_from(&ws_url, "http://elsewhere.example"), 403);
    let (address, _) = host.rsplit_once(':').expect("host:port");
    assert_eq!(handshake_from(&ws_url, &format!("http://{address}:1")), 403);
    assert_eq!(handshake_from(&ws_url, &format!("http://{host}")), 101);

    // A goal reaches operator/goal; garbage is refused, each counted once.
    socket
        .send(Message::text(
            json!({"goal": {"x": 3.5, "y": 4.25}}).to_string(),
        ))
        .expect("send a goal");
    socket.send(Message::text("{not json")).expect("send");
    socket
        .send(Message::text(r#"{"goal":{"x":NaN,"y":1}}"#))
        .expect("send");
    socket
        .send(Message::text(r#"{"timeline":{"op":"play"}}"#))
        .expect("send a recording's op to a live view");
    let rejected_after = |socket: &mut Socket, at_least: u64| {
        let deadline = Instant::now() + READ_TIMEOUT;
        loop {
            let frame = next_frame(socket);
            let rejected = frame["rejected_inputs"].as_u64().expect("rejected_inputs");
            if rejected >= at_least || Instant::now() > deadline {
                return (rejected, frame["tick"].as_u64().expect("tick"));
            }
        }
    };
    assert_eq!(rejected_after(&mut socket, 3).0, 3);
    let deadline = Instant::now() + READ_TIMEOUT;
    while witness.goal.latest().is_none() && Instant::now() < deadline {
        witness.goal.drain(|_| {});
        std::thread::sleep(Duration::from_millis(20));
    }
    let goal = witness.goal.latest().expect("the goal on operator/goal");
    assert_eq!((goal.x, goal.y, goal.tolerance), (3.5, 4.25, 0.0));

    // A message over the cap: the view closes that connection and counts it.
    let _ = socket.send(Message::text("x".repeat(1 << 20)));
    let _ = socket.flush();
    let mut socket = connect(&ws_url);
    let (rejected, tick_before) = rejected_after(&mut socket, 4);
    assert_eq!(rejected, 4);
    let (_, tick_after) = {
        std::thread::sleep(Duration::from_millis(500));
        rejected_after(&mut socket, 4)
    };
    assert!(
        tick_after > tick_before,
        "the stack stopped after the garbage"
    );
    assert_eq!(
        pid_of(&stack.namespace, "mole-view"),
        Some(view),
        "the view is not the one that got the garbage"
    );
    assert_eq!(
        view_starts(&stack.out),
        1,
        "the view was restarted:\n{}",
        logs(&stack.out)
    );
}

/// A view killed beside `mole up` is started again by its policy on the port the page knows
/// (`--view=0` included): a page that reconnects gets frames again, from a stack that never
/// stopped; the view's log says it started twice.
#[test]
fn a_killed_view_is_started_again_on_its_port() {
    let _serial = serial();
    let mut stack = Stack::start("view-restart", RUN);
    let lines = stack.stdout_lines().expect("stdout");
    let url = view_url(&lines, Duration::from_secs(60));
    let ws_url = format!("{}ws", url.replacen("http://", "ws://", 1));
    let mut socket = connect(&ws_url);
    let before = next_frame(&mut socket)["tick"].as_u64().expect("tick");
    let world = pid_of(&stack.namespace, "mole-world");
    let killed = pid_of(&stack.namespace, "mole-view").expect("the view runs");
    signal(killed, nix::sys::signal::Signal::SIGKILL);
    wait_for_new_pid(
        &stack.namespace,
        "mole-view",
        Some(killed),
        Duration::from_secs(30),
        &stack.out,
    );
    // The page's way: try again until the view serves.
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut socket = loop {
        match tungstenite::connect(&ws_url) {
            Ok(_) => break connect(&ws_url),
            Err(e) if Instant::now() > deadline => panic!("no view at {ws_url} again: {e}"),
            Err(_) => std::thread::sleep(Duration::from_millis(100)),
        }
    };
    let first = next_frame(&mut socket);
    assert_eq!(
        first["full"], true,
        "a new view starts each page whole: {first}"
    );
    // A view that just started may send its map before the first truth it reads (tick 0).
    let later = frame_where(&mut socket, "after the kill", |f| {
        f["tick"].as_u64().is_some_and(|tick| tick > before)
    });
    assert!(later["tick"].as_u64() > Some(before));
    assert_eq!(
        pid_of(&stack.namespace, "mole-world"),
        world,
        "the stack went on as it was"
    );
    assert_eq!(view_starts(&stack.out), 2, "{}", logs(&stack.out));
}

/// `mole up --view-no-controls`: the page is told it only watches (`controls` false), and a
/// goal, a pause and a step are refused and counted, none reaching operator/goal or
/// operator/pace; the run goes on unpaused.
#[test]
fn a_watch_only_view_refuses_and_counts_every_input() {
    let _serial = serial();
    let args: Vec<&str> = RUN.iter().copied().chain(["--view-no-controls"]).collect();
    let mut stack = Stack::start("view-watch-only", &args);
    let lines = stack.stdout_lines().expect("stdout");
    let url = view_url(&lines, Duration::from_secs(60));
    let ws_url = format!("{}ws", url.replacen("http://", "ws://", 1));
    let ctx = join_realtime_stack(&stack.namespace, "view-operator-witness");
    let mut goal = ctx.passive_subscriber(topics::OPERATOR_GOAL).expect("goal");
    let mut pace = ctx.passive_subscriber(topics::OPERATOR_PACE).expect("pace");
    let mut socket = connect(&ws_url);
    let first = next_frame(&mut socket);
    assert_eq!(first["controls"], false, "{first}");
    assert_eq!(first["rejected_inputs"], 0);
    send(&mut socket, json!({"goal": {"x": 3.0, "y": 3.0}}));
    send(&mut socket, json!({"pace": "pause"}));
    send(&mut socket, json!({"pace": "step", "steps": 5}));
    let counted = frame_where(&mut socket, "counting 3 refused inputs", |f| {
        f["rejected_inputs"] == 3
    });
    // The view reads its pages' inputs before it makes a frame: what it would have published
    // is out by the frame after the one that counted them.
    let seq = counted["seq"].as_u64().expect("seq");
    let later = frame_where(&mut socket, "two frames later", |f| {
        f["seq"].as_u64() >= Some(seq + 2)
    });
    assert_eq!(later["controls"], false);
    assert_eq!(later["rejected_inputs"], 3);
    assert!(
        later["tick"].as_u64() > counted["tick"].as_u64(),
        "the run paused"
    );
    assert_eq!(
        (goal.drain(|_| {}), pace.drain(|_| {})),
        (0, 0),
        "a watch-only view published a goal or a pace"
    );
    assert!(goal.latest().is_none() && pace.latest().is_none());
}

/// `mole view --port P` beside a running stack, P in use, is refused with exit 2 (`mole up
/// --view=P`: tests/bad_input.rs); `mole view --bind 0.0.0.0` warns that anyone who can reach it
/// can watch the run (watch-only here: `--no-controls`), then serves.
#[test]
fn a_port_in_use_is_refused_and_serving_beyond_loopback_is_warned_of() {
    let _serial = serial();
    let taken = std::net::TcpListener::bind("127.0.0.1:0").expect("a port");
    let port = taken.local_addr().expect("its address").port().to_string();

    let mut stack = Stack::start("view-port", RUN);
    // The stack's own view serves once the stack runs: then `mole view` finds it. (The lines
    // are kept, so that `mole up` always has a reader.)
    let stack_lines = stack.stdout_lines().expect("stdout");
    view_url(&stack_lines, Duration::from_secs(60));
    let ns = stack.namespace.clone();
    let in_use = view_command(&ns, &["--port", &port])
        .output()
        .expect("mole view");
    let stderr = String::from_utf8_lossy(&in_use.stderr);
    assert_eq!(in_use.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains(&format!("cannot serve the view on 127.0.0.1:{port}")),
        "{stderr}"
    );

    let args = ["--bind", "0.0.0.0", "--port", "0", "--no-controls"];
    let mut elsewhere = view_command(&ns, &args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("mole view --bind");
    let stdout = elsewhere.stdout.take().expect("stdout");
    let stderr = elsewhere.stderr.take().expect("stderr");
    let (lines, said) = (lines_of(stdout), lines_of(stderr));
    let url = view_url(&lines, Duration::from_secs(60));
    let served = url
        .strip_prefix("http://0.0.0.0:")
        .expect("served on 0.0.0.0");
    let mut socket = connect(&format!("ws://127.0.0.1:{}ws", served));
    assert_eq!(next_frame(&mut socket)["controls"], false);
    signal(elsewhere.id(), nix::sys::signal::Signal::SIGINT);
    let status = elsewhere.wait().expect("mole view ends");
    let warned: Vec<String> = std::iter::from_fn(|| said.recv_timeout(READ_TIMEOUT).ok()).collect();
    assert!(
        warned
            .iter()
            .any(|l| l
                .contains("the view serves on 0.0.0.0: anyone who can reach it can watch the run")),
        "no warning: {warned:?}"
    );
    assert!(status.success(), "mole view at Ctrl-C: {status}");
    drop(stack);
}

/// `mole view --namespace NAMESPACE ARGS`, run from the workspace root.
fn view_command(namespace: &str, args: &[&str]) -> Command {
    let mut command = Command::new(bin_dir().join("mole"));
    command
        .current_dir(workspace())
        .env_remove("CARGO")
        .env_remove("CARGO_MANIFEST_DIR")
        .args(["view", "--namespace", namespace])
        .args(args)
        .stdin(Stdio::null());
    command
}

/// The lines of `pipe`, from a thread that reads it to its end.
fn lines_of(pipe: impl std::io::Read + Send + 'static) -> std::sync::mpsc::Receiver<String> {
    let (sender, lines) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(pipe).lines().map_while(Result::ok) {
            if sender.send(line).is_err() {
                break;
            }
        }
    });
    lines
}

// ---------------------------------------------------------------------------------------------
// Headless Chromium
// ---------------------------------------------------------------------------------------------

/// Chromium as Debian installs it, or on PATH.
fn chromium() -> Option<std::path::PathBuf> {
    let installed = std::path::PathBuf::from("/usr/bin/chromium");
    if installed.exists() {
        return Some(installed);
    }
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .flat_map(|dir| [dir.join("chromium"), dir.join("chromium-browser")])
        .find(|p| p.exists())
}

/// A headless Chromium, killed (and its profile removed) however the test ends.
struct Browser {
    child: Child,
    profile: std::path::PathBuf,
    /// The browser's DevTools WebSocket.
    devtools: String,
}

impl Browser {
    fn start(program: &std::path::Path) -> Browser {
        let profile =
            std::env::temp_dir().join(format!("mole-view-chromium-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&profile);
        let mut child = Command::new(program)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--window-size=1280,800",
            ])
            .arg(format!("--user-data-dir={}", profile.display()))
            .args(["--remote-debugging-port=0", "about:blank"])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start chromium");
        let stderr = child.stderr.take().expect("stderr");
        let (found, devtools) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                if let Some(url) = line.strip_prefix("DevTools listening on ") {
                    let _ = found.send(url.trim().to_string());
                }
            }
        });
        let mut browser = Browser {
            child,
            profile,
            devtools: String::new(),
        };
        browser.devtools = devtools
            .recv_timeout(Duration::from_secs(30))
            .expect("chromium said where DevTools listens");
        browser
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        // Chromium's helper processes may still write into the profile while they exit.
        for _ in 0..40 {
            if std::fs::remove_dir_all(&self.profile).is_ok() || !self.profile.exists() {
                break;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

/// A Chrome DevTools Protocol client on one page (a flattened session).
struct DevTools {
    socket: Socket,
    next_id: u64,
    session: Option<String>,
    /// Console errors and exceptions the page reported.
    problems: Vec<String>,
}

impl DevTools {
    /// A new page of `browser` at `url`, its errors and console watched.
    fn open(browser: &Browser, url: &str) -> DevTools {
        let mut devtools = DevTools {
            socket: connect(&browser.devtools),
            next_id: 0,
            session: None,
            problems: Vec::new(),
        };
        let target = devtools.call("Target.createTarget", json!({"url": "about:blank"}));
        let attached = devtools.call(
            "Target.attachToTarget",
            json!({"targetId": target["targetId"], "flatten": true}),
        );
        devtools.session = attached["sessionId"].as_str().map(str::to_string);
        for domain in ["Runtime.enable", "Log.enable", "Page.enable"] {
            devtools.call(domain, json!({}));
        }
        devtools.call(
            "Emulation.setDeviceMetricsOverride",
            json!({"width": 1280, "height": 800, "deviceScaleFactor": 1, "mobile": false}),
        );
        devtools.call("Page.navigate", json!({"url": url}));
        devtools
    }

    /// The value of a JavaScript expression in the page (JSON-able).
    fn evaluate(&mut self, expression: &str) -> Value {
        let result = self.call(
            "Runtime.evaluate",
            json!({"expression": expression, "returnByValue": true}),
        );
        result["result"]["value"].clone()
    }

    fn call(&mut self, method: &str, params: Value) -> Value {
        self.next_id += 1;
        let id = self.next_id;
        let mut request = json!({"id": id, "method": method, "params": params});
        if let Some(session) = &self.session {
            request["sessionId"] = json!(session);
        }
        self.socket
            .send(Message::text(request.to_string()))
            .expect("send to DevTools");
        loop {
            let Message::Text(text) = self.socket.read().expect("DevTools answers") else {
                continue;
            };
            let message: Value = serde_json::from_str(&text).expect("DevTools speaks JSON");
            if message["id"] == id {
                assert!(message.get("error").is_none(), "{method}: {message}");
                return message["result"].clone();
            }
            self.note(&message);
        }
    }

    /// Keeps what an event says of errors.
    fn note(&mut self, event: &Value) {
        let params = &event["params"];
        match event["method"].as_str() {
            Some("Runtime.exceptionThrown") => self.problems.push(params.to_string()),
            Some("Runtime.consoleAPICalled") if params["type"] == "error" => {
                self.problems.push(params.to_string())
            }
            Some("Log.entryAdded") if params["entry"]["level"] == "error" => {
                self.problems.push(params.to_string())
            }
            _ => {}
        }
    }

    /// `window.moleView` as JSON.
    fn view_state(&mut self) -> Value {
        let result = self.call(
            "Runtime.evaluate",
            json!({"expression": "JSON.stringify(window.moleView ? {frames: moleView.frames, robot: moleView.robot, filled: moleView.filledCells, errors: moleView.errors} : null)", "returnByValue": true}),
        );
        serde_json::from_str(result["result"]["value"].as_str().unwrap_or("null"))
            .expect("moleView as JSON")
    }
}

/// In a real browser the page draws the robot moving and the frontier grid filling over a few
/// seconds, with no console error and no exception. With MOLE_VIEW_SCREENSHOT=FILE.png it also
/// saves a screenshot there (docs/img/view.png).
#[test]
fn the_page_shows_the_robot_moving_and_the_map_filling_in_chromium() {
    const TEST: &str = "the_page_shows_the_robot_moving_and_the_map_filling_in_chromium";
    let Some(program) = chromium() else {
        return skip(
            TEST,
            "no chromium (/usr/bin/chromium, chromium or chromium-browser on PATH); scripts/browser-env.sh installs it",
        );
    };
    let _serial = serial();
    let mut stack = Stack::start("view-page", RUN);
    let lines = stack.stdout_lines().expect("stdout");
    let url = view_url(&lines, Duration::from_secs(60));
    let browser = Browser::start(&program);
    let mut devtools = DevTools::open(&browser, &url);

    let mut states = Vec::new();
    let started = Instant::now();
    while started.elapsed() < WATCH + Duration::from_secs(1) {
        std::thread::sleep(Duration::from_millis(250));
        let state = devtools.view_state();
        if state["frames"].as_u64().unwrap_or(0) > 0 && state["robot"].is_object() {
            states.push(state);
        }
    }
    if let Some(file) = std::env::var_os("MOLE_VIEW_SCREENSHOT") {
        use base64::Engine as _;
        let shot = devtools.call("Page.captureScreenshot", json!({"format": "png"}));
        let png = base64::engine::general_purpose::STANDARD
            .decode(shot["data"].as_str().expect("screenshot data"))
            .expect("base64 png");
        std::fs::write(&file, png).expect("write the screenshot");
    }
    // Events that came after the last call.
    if let MaybeTlsStream::Plain(stream) = devtools.socket.get_ref() {
        stream
            .set_read_timeout(Some(Duration::from_millis(300)))
            .expect("read timeout");
    }
    while let Ok(message) = devtools.socket.read() {
        if let Message::Text(text) = message {
            devtools.note(&serde_json::from_str(&text).expect("DevTools speaks JSON"));
        }
    }

    assert!(
        states.len() >= 4,
        "the page drew too few frames: {states:?}"
    );
    let (first, last) = (&states[0], &states[states.len() - 1]);
    let moved = (last["robot"]["x"].as_f64().unwrap() - first["robot"]["x"].as_f64().unwrap())
        .hypot(last["robot"]["y"].as_f64().unwrap() - first["robot"]["y"].as_f64().unwrap());
    assert!(
        moved > 0.01 && last["robot"]["tick"].as_u64() > first["robot"]["tick"].as_u64(),
        "the robot marker did not move: {first} → {last}"
    );
    assert!(
        last["filled"].as_u64() > first["filled"].as_u64(),
        "the grid did not fill: {first} → {last}"
    );
    assert!(last["frames"].as_u64() > first["frames"].as_u64());
    assert_eq!(last["errors"], json!([]), "the page's own error list");
    assert!(
        devtools.problems.is_empty(),
        "console errors or exceptions: {:?}",
        devtools.problems
    );
    drop(browser);
    drop(stack);
}

// ---------------------------------------------------------------------------------------------
// A recording in the view: `mole view FILE`
// ---------------------------------------------------------------------------------------------

/// Lockstep steps of the recorded run.
const RECORDED_TICKS: &str = "600";

/// Records a lockstep run of [`RECORDED_TICKS`] steps into `dir`/run.mcap.
fn record_lockstep(dir: &std::path::Path) -> std::path::PathBuf {
    let file = dir.join("run.mcap");
    let args = [
        "launch/stacks/lockstep.toml",
        "--ticks",
        RECORDED_TICKS,
        "--record",
        file.to_str().expect("a UTF-8 temp path"),
    ];
    let output = Stack::start("view-rec", &args).wait(Duration::from_secs(120));
    assert!(
        output.status.success(),
        "the recorded run failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    file
}

/// The recorded truths by tick, `(x, y, theta)`, read with the MCAP library alone.
fn recorded_truths(file: &std::path::Path) -> BTreeMap<u64, (f64, f64, f64)> {
    let bytes = std::fs::read(file).expect("the recording");
    mcap::MessageStream::new(&bytes)
        .expect("an MCAP file")
        .map(|m| m.expect("a complete recording"))
        .filter(|m| m.channel.topic == topics::WORLD_TRUTH.name)
        .map(|m| {
            let t = bytemuck::pod_read_unaligned::<Truth>(&m.data);
            (t.header.tick, (t.x, t.y, t.theta))
        })
        .collect()
}

/// A running `mole view FILE` (environment naming `namespace`, so its view is found and
/// killed with it); on drop (a failed test included) it and its view are stopped.
struct RecordingView {
    namespace: String,
    child: Option<Child>,
    lines: std::sync::mpsc::Receiver<String>,
}

impl RecordingView {
    fn start(file: &std::path::Path) -> RecordingView {
        let namespace = unique_namespace("view-file");
        let mut child = Command::new(bin_dir().join("mole"))
            .current_dir(workspace())
            .env_remove("CARGO")
            .env_remove("CARGO_MANIFEST_DIR")
            .env(mole_types::env::NAMESPACE, &namespace)
            .env("RUST_LOG", "warn")
            .arg("view")
            .arg(file)
            .args(["--port", "0"])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .spawn()
            .expect("start mole view FILE");
        let stdout = child.stdout.take().expect("stdout");
        let (sender, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if sender.send(line).is_err() {
                    break;
                }
            }
        });
        RecordingView {
            namespace,
            child: Some(child),
            lines,
        }
    }

    /// Ctrl-C: `mole view` and its view end, with exit 0.
    fn interrupt(mut self) {
        let mut child = self.child.take().expect("running");
        signal(child.id(), nix::sys::signal::Signal::SIGINT);
        let deadline = Instant::now() + READ_TIMEOUT;
        while child.try_wait().ok().flatten().is_none() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(50));
        }
        let status = child.try_wait().ok().flatten();
        let _ = child.kill();
        let _ = child.wait();
        assert!(
            status.is_some_and(|s| s.success()),
            "mole view did not end with exit 0 at Ctrl-C: {status:?}"
        );
        assert_eq!(processes_of(&self.namespace), Vec::<u32>::new());
    }
}

impl Drop for RecordingView {
    fn drop(&mut self) {
        stop_and_clean(self.child.take(), &self.namespace);
    }
}

/// Sends a page's input (JSON text).
fn send(socket: &mut Socket, input: Value) {
    socket
        .send(Message::text(input.to_string()))
        .expect("send to the view");
}

/// The first frame that satisfies `wanted`, within [`READ_TIMEOUT`].
fn frame_where(socket: &mut Socket, what: &str, mut wanted: impl FnMut(&Value) -> bool) -> Value {
    let deadline = Instant::now() + READ_TIMEOUT;
    loop {
        let frame = next_frame(socket);
        if wanted(&frame) {
            return frame;
        }
        assert!(
            Instant::now() < deadline,
            "no frame {what}; the last: {frame}"
        );
    }
}

/// The timeline's current tick of a frame.
fn timeline_tick(frame: &Value) -> u64 {
    frame["timeline"]["tick"].as_u64().expect("timeline tick")
}

/// `mole view FILE` of a recorded lockstep run, with no stack running and no iceoryx2 file of
/// its making: the first frame holds the arena and a timeline spanning the recorded truths,
/// paused at the first; a seek shows the recorded true pose of that tick; at 10× play moves on
/// and reaches the last tick; paused, the tick holds across frames half a second apart; garbage
/// and a live view's inputs (a goal, a pace) are refused and counted; Ctrl-C ends it with 0.
#[test]
fn a_recording_plays_seeks_and_pauses_in_the_view() {
    let _serial = serial();
    let dir = TempDir::new("view-rec");
    let file = record_lockstep(&dir.0);
    let truths = recorded_truths(&file);
    let (&first, &last) = (
        truths.keys().next().expect("truths"),
        truths.keys().next_back().expect("truths"),
    );
    assert_eq!(last, RECORDED_TICKS.parse::<u64>().unwrap());

    let view = RecordingView::start(&file);
    let url = view_url(&view.lines, READ_TIMEOUT);
    let ws_url = format!("{}ws", url.replacen("http://", "ws://", 1));
    let mut socket = connect(&ws_url);
    let frame = next_frame(&mut socket);
    assert_eq!(frame["full"], true, "{frame}");
    assert!(frame["arena"]["width"].as_f64() > Some(0.0), "{frame}");
    assert_eq!(
        frame["timeline"],
        json!({"first_tick": first, "last_tick": last, "tick": first, "playing": false,
               "speed": 1.0})
    );
    assert_eq!(frame["truth"]["tick"], first);
    assert_eq!(frame["controls"], false);
    let pids: std::collections::BTreeSet<u32> = processes_of(&view.namespace).into_iter().collect();
    assert_eq!(pids.len(), 2, "mole and mole-view: {pids:?}");
    assert!(pid_of(&view.namespace, "mole-view").is_some());

    // A seek: the next frames show the recorded truth of that tick.
    let at = 321;
    send(&mut socket, json!({"timeline": {"op": "seek", "tick": at}}));
    let mut sought = frame_where(&mut socket, "at the sought tick", |f| {
        timeline_tick(f) == at
    });
    for _ in 0..3 {
        let truth = &sought["truth"];
        assert_eq!(truth["tick"], at, "timeline {}", sought["timeline"]);
        let (x, y, theta) = truths[&at];
        for (field, recorded) in [("x", x), ("y", y), ("theta", theta)] {
            let shown = truth[field].as_f64().expect("a number");
            assert!(
                (shown - recorded).abs() <= 1e-12 * recorded.abs().max(1.0),
                "truth {field} at tick {at}: frame {shown}, recorded {recorded}"
            );
        }
        sought = next_frame(&mut socket);
    }

    // Garbage, a goal and a pace: refused, each counted.
    socket.send(Message::text("{not json")).expect("send");
    send(&mut socket, json!({"goal": {"x": 1.0, "y": 1.0}}));
    send(&mut socket, json!({"pace": "pause"}));
    send(
        &mut socket,
        json!({"timeline": {"op": "speed", "speed": 1000}}),
    );
    frame_where(&mut socket, "counting 4 refused inputs", |f| {
        f["rejected_inputs"] == 4
    });

    // Play at 10×: the tick moves on, never back, and reaches the end, where play stops.
    send(
        &mut socket,
        json!({"timeline": {"op": "speed", "speed": 10}}),
    );
    send(&mut socket, json!({"timeline": {"op": "play"}}));
    let mut ticks = Vec::new();
    let end = frame_where(&mut socket, "at the last tick", |f| {
        ticks.push(timeline_tick(f));
        timeline_tick(f) == last
    });
    assert!(ticks.windows(2).all(|w| w[0] <= w[1]), "{ticks:?}");
    assert!(
        ticks.iter().any(|t| (at + 1..last).contains(t)),
        "no tick between {at} and {last}: {ticks:?}"
    );
    assert_eq!(end["timeline"]["playing"], false, "{end}");
    assert_eq!(end["timeline"]["speed"], 10.0);
    assert_eq!(end["truth"]["tick"], last);

    // Pause while playing: the tick holds across frames at least half a second apart (ten of
    // the view's 50 ms frames).
    send(
        &mut socket,
        json!({"timeline": {"op": "speed", "speed": 1}}),
    );
    send(
        &mut socket,
        json!({"timeline": {"op": "seek", "tick": 100}}),
    );
    send(&mut socket, json!({"timeline": {"op": "play"}}));
    frame_where(&mut socket, "playing on from tick 100", |f| {
        f["timeline"]["playing"] == true && timeline_tick(f) > 100
    });
    send(&mut socket, json!({"timeline": {"op": "pause"}}));
    let paused = frame_where(&mut socket, "paused", |f| f["timeline"]["playing"] == false);
    assert!(
        timeline_tick(&paused) < last,
        "it stopped at the end, not paused: {paused}"
    );
    let seq = paused["seq"].as_u64().expect("seq");
    let later = frame_where(&mut socket, "half a second later", |f| {
        f["seq"].as_u64() >= Some(seq + 10)
    });
    assert_eq!(timeline_tick(&later), timeline_tick(&paused));
    assert_eq!(later["truth"]["tick"], paused["truth"]["tick"]);
    assert_eq!(later["rejected_inputs"], 4);

    let made: Vec<String> = made_by(&shm_files(), &pids);
    assert!(
        made.is_empty(),
        "the recording's view made iceoryx2 files: {made:?}"
    );
    drop(socket);
    view.interrupt();
}

/// A file `mole view` cannot show is refused with exit 2, naming it and what is wrong, before
/// anything is served: a truncated recording, a file that is not MCAP, a missing one; and a
/// recording with --namespace.
#[test]
fn a_recording_the_view_cannot_read_is_refused_before_serving() {
    let _serial = serial();
    let dir = TempDir::new("view-bad");
    let file = record_lockstep(&dir.0);
    let bytes = std::fs::read(&file).expect("the recording");
    let cut = dir.0.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).expect("write the cut file");
    let text = dir.0.join("notes.mcap");
    std::fs::write(&text, "not a recording").expect("write");
    let missing = dir.0.join("missing.mcap");
    for (path, why) in [
        (&cut, "a truncated MCAP file"),
        (&text, "not an MCAP file"),
        (&missing, "No such file"),
    ] {
        let shown = path.to_str().expect("a UTF-8 temp path");
        let output = run_mole(&["view", shown, "--port", "0"]);
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{shown}: {stderr}");
        assert!(
            stderr.contains(&format!("error: {shown}: {why}")),
            "{shown}: {stderr}"
        );
        assert!(
            !String::from_utf8_lossy(&output.stdout).contains("view: "),
            "{shown} was served"
        );
    }
    let output = run_mole(&["view", file.to_str().unwrap(), "--namespace", "robot0"]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("--namespace"), "{stderr}");
}

/// In a real browser a recording's page shows its timeline (and no operator controls) over the
/// recorded span; its play button and speed selector play the recording to its end; no console
/// error, no exception.
#[test]
fn a_recording_plays_from_its_timeline_in_chromium() {
    const TEST: &str = "a_recording_plays_from_its_timeline_in_chromium";
    let Some(program) = chromium() else {
        return skip(
            TEST,
            "no chromium (/usr/bin/chromium, chromium or chromium-browser on PATH); scripts/browser-env.sh installs it",
        );
    };
    let _serial = serial();
    let dir = TempDir::new("view-page-rec");
    let file = record_lockstep(&dir.0);
    let last: u64 = RECORDED_TICKS.parse().unwrap();
    let view = RecordingView::start(&file);
    let url = view_url(&view.lines, READ_TIMEOUT);
    let browser = Browser::start(&program);
    let mut devtools = DevTools::open(&browser, &url);
    let page = "JSON.stringify({frames: moleView.frames, tick: moleView.tick, errors: \
                moleView.errors, timeline: !document.getElementById('timeline').hidden, \
                controls: !document.getElementById('controls').hidden, \
                seek_max: Number(document.getElementById('seek').max)})";
    let state = |devtools: &mut DevTools| -> Value {
        serde_json::from_str(devtools.evaluate(page).as_str().unwrap_or("null"))
            .unwrap_or(Value::Null)
    };
    let deadline = Instant::now() + READ_TIMEOUT;
    let mut shown = state(&mut devtools);
    while shown["frames"].as_u64().unwrap_or(0) == 0 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(100));
        shown = state(&mut devtools);
    }
    assert_eq!(
        (
            &shown["timeline"],
            &shown["controls"],
            &shown["seek_max"],
            &shown["tick"]
        ),
        (&json!(true), &json!(false), &json!(last), &json!(0)),
        "{shown}"
    );
    devtools.evaluate(
        "const s = document.getElementById('speed'); s.value = '20'; \
         s.dispatchEvent(new Event('change')); document.getElementById('play').click();",
    );
    let deadline = Instant::now() + READ_TIMEOUT;
    let mut ticks = Vec::new();
    while shown["tick"].as_u64() != Some(last) && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(100));
        shown = state(&mut devtools);
        ticks.extend(shown["tick"].as_u64());
    }
    assert_eq!(shown["tick"], last, "played only to {ticks:?}");
    assert!(ticks.iter().any(|t| (1..last).contains(t)), "{ticks:?}");
    assert_eq!(shown["errors"], json!([]), "the page's own error list");
    assert!(
        devtools.problems.is_empty(),
        "console errors or exceptions: {:?}",
        devtools.problems
    );
    drop(browser);
    view.interrupt();
}
