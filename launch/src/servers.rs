//! The servers that show a stack: the live view (`mole view`, `mole up --view`; `mole view FILE`
//! for a recording, with a timeline) and the Foxglove server (`mole foxglove`, `mole up
//! --foxglove`; `mole foxglove FILE` for a recording, with playback control).
//!
//! Each is its own process (`mole-view`, `mole-foxglove`), an observer of the stack that is none
//! of its roles: a [`Sidecar`], stopped after every role; if it dies the run goes on without it,
//! with a warning. It writes its URL into a file once it serves; the launcher prints it as
//! `view: URL` or `foxglove: URL`. A recording's server (`--file FILE`) needs no stack and opens
//! no IPC: the launcher only starts it, prints its URL and stops it at Ctrl-C.

use crate::Failure;
use crate::sidecar::{self, Attached, Sidecar};
use crate::supervisor::dies_with_the_launcher;
use crate::{RestartPolicy, RestartWhen};
use clap::Args;
use mole_types::env;
use mole_types::graph::nodes;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// A server that shows the stack.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Server {
    /// Its name in its log file, its supervisor and the launcher's output (`view: URL`).
    pub name: &'static str,
    pub program: &'static str,
    pub default_port: u16,
    /// What it is called in a sentence.
    pub title: &'static str,
    /// What a client can do beside watching, unless --no-controls.
    pub steers: &'static str,
    /// How the run goes on once it gave up restarting it.
    pub without: &'static str,
}

/// The live view in a browser.
pub const VIEW: Server = Server {
    name: nodes::VIEW,
    program: mole_view::VIEW_PROGRAM,
    default_port: mole_view::DEFAULT_PORT,
    title: "the view",
    steers: "steer the robot (goals, pause, step; --no-controls turns that off)",
    without: "without the view",
};

/// The Foxglove server, for the Foxglove app and Lichtblick (its crate's program and port: the
/// launcher does not depend on it, a test checks them).
pub const FOXGLOVE: Server = Server {
    name: nodes::FOXGLOVE,
    program: "mole-foxglove",
    default_port: 8765,
    title: "the Foxglove server",
    steers: "steer the robot, change its settings and swap its processes (--no-controls turns \
             that off)",
    without: "without the Foxglove server",
};

/// Beside `mole up` a server that died is started again (a page or Foxglove reconnects by
/// itself), on the same port; after five restarts the run goes on without it.
const RESTART: RestartPolicy = RestartPolicy {
    policy: RestartWhen::OnFailure,
    backoff_ms: 200,
    max_backoff_ms: 5000,
    max: 5,
    stable_after_ms: 10_000,
};

/// Where and how a server serves (`mole view`'s and `mole foxglove`'s flags).
#[derive(Debug, Clone, Args)]
pub struct ServeArgs {
    /// The port to serve on (default: the view 7777, Foxglove 8765; 0: any free port).
    #[arg(long)]
    pub port: Option<u16>,
    /// The address to serve on. Anything but loopback lets anyone who can reach it watch the
    /// run and, unless --no-controls, steer the robot.
    #[arg(long, default_value_t = IpAddr::V4(Ipv4Addr::LOCALHOST))]
    pub bind: IpAddr,
    /// No goals, pauses or steps (and with Foxglove no setting changes or swaps) from clients:
    /// they only watch.
    #[arg(long)]
    pub no_controls: bool,
}

#[derive(Debug, Clone, Args)]
pub struct ViewArgs {
    /// A recording (`mole up --record FILE`) to show instead of a running stack, with a
    /// timeline: play, pause, seek, speed.
    pub file: Option<PathBuf>,
    /// Namespace of the running stack (not with FILE: a recording needs no stack).
    #[arg(long, default_value = mole_types::env::DEFAULT_NAMESPACE, conflicts_with = "file")]
    pub namespace: String,
    #[command(flatten)]
    pub serve: ServeArgs,
}

/// `mole up`'s flags for a view beside the stack.
#[derive(Debug, Clone, Default, Args)]
pub struct UpViewArgs {
    /// Serve a live view of the run in a browser, on PORT (default 7777; 0: any free port); its
    /// URL is printed as `view: URL`.
    #[arg(id = "view", long = "view", value_name = "PORT", num_args = 0..=1, require_equals = true)]
    pub port: Option<Option<u16>>,
    /// With --view: the address to serve on (default 127.0.0.1; anything else lets anyone who
    /// can reach it watch and, unless --view-no-controls, steer the robot).
    #[arg(long = "view-bind", value_name = "ADDR", requires = "view")]
    pub bind: Option<IpAddr>,
    /// With --view: no goals, pauses or steps from the page.
    #[arg(long = "view-no-controls", requires = "view")]
    pub no_controls: bool,
}

/// `mole up`'s flags for the Foxglove server beside the stack.
#[derive(Debug, Clone, Default, Args)]
pub struct UpFoxgloveArgs {
    /// Serve the run to the Foxglove app (or Lichtblick) over the Foxglove WebSocket protocol,
    /// on PORT (default 8765; 0: any free port); its URL is printed as `foxglove: URL`.
    #[arg(id = "foxglove", long = "foxglove", value_name = "PORT", num_args = 0..=1, require_equals = true)]
    pub port: Option<Option<u16>>,
    /// With --foxglove: the address to serve on (default 127.0.0.1; anything else lets anyone
    /// who can reach it watch and, unless --foxglove-no-controls, steer the robot, change its
    /// settings and swap its processes).
    #[arg(
        id = "foxglove_bind",
        long = "foxglove-bind",
        value_name = "ADDR",
        requires = "foxglove"
    )]
    pub bind: Option<IpAddr>,
    /// With --foxglove: no goals, paces, setting changes or swaps from clients.
    #[arg(
        id = "foxglove_no_controls",
        long = "foxglove-no-controls",
        requires = "foxglove"
    )]
    pub no_controls: bool,
}

/// The server `server` to start beside the stack, if its flag (`port`) asks for one.
fn plan_beside(
    server: Server,
    port: Option<Option<u16>>,
    bind: Option<IpAddr>,
    no_controls: bool,
) -> Result<Option<ServerPlan>, Failure> {
    let Some(port) = port else {
        return Ok(None);
    };
    let serve = ServeArgs {
        port,
        bind: bind.unwrap_or(IpAddr::V4(Ipv4Addr::LOCALHOST)),
        no_controls,
    };
    ServerPlan::new(server, serve).map(Some)
}

impl UpViewArgs {
    /// The view to start beside the stack, if --view asks for one.
    pub fn plan(&self) -> Result<Option<ServerPlan>, Failure> {
        plan_beside(VIEW, self.port, self.bind, self.no_controls)
    }
}

impl UpFoxgloveArgs {
    /// The Foxglove server to start beside the stack, if --foxglove asks for one.
    pub fn plan(&self) -> Result<Option<ServerPlan>, Failure> {
        plan_beside(FOXGLOVE, self.port, self.bind, self.no_controls)
    }
}

impl ServeArgs {
    fn port(&self, server: Server) -> u16 {
        self.port.unwrap_or(server.default_port)
    }

    /// Refuses, before anything starts, a port that something else serves on already (0, any
    /// free port, always works). `flag` is the option that named it.
    fn check_port(&self, server: Server, flag: &str) -> Result<(), Failure> {
        let port = self.port(server);
        if port == 0 {
            return Ok(());
        }
        let address = SocketAddr::new(self.bind, port);
        std::net::TcpListener::bind(address).map(drop).map_err(|e| {
            Failure::input(format!(
                "{flag}={port}: cannot serve {} on {address}: {e}; expected a free port (0 takes \
                 any)",
                server.title
            ))
        })
    }

    /// The server's arguments; warns when it serves beyond this machine.
    fn server_args(&self, server: Server, ready: &Path) -> Vec<String> {
        if !self.bind.is_loopback() {
            let steer = match self.no_controls {
                true => "watch the run".to_string(),
                false => format!("watch the run and {}", server.steers),
            };
            tracing::warn!(
                "{} serves on {}: anyone who can reach it can {steer}",
                server.title,
                self.bind
            );
        }
        let mut args = vec![
            "--port".to_string(),
            self.port(server).to_string(),
            "--bind".to_string(),
            self.bind.to_string(),
            "--ready-file".to_string(),
            ready.display().to_string(),
        ];
        if self.no_controls {
            args.push("--no-controls".to_string());
        }
        args
    }
}

/// The file `server` writes its URL into, fresh (a stale one removed).
fn ready_file(server: Server) -> PathBuf {
    let name = format!("mole-{}-{}.url", server.name, std::process::id());
    let file = std::env::temp_dir().join(name);
    let _ = std::fs::remove_file(&file);
    file
}

/// Reads the URL `server` wrote, prints it as `NAME: URL` and removes the file.
fn announce(server: Server, ready: &Path) -> bool {
    let Ok(url) = std::fs::read_to_string(ready) else {
        return false;
    };
    let _ = std::fs::remove_file(ready);
    println!("{}: {}", server.name, url.trim());
    true
}

/// What `mole up --view` or `--foxglove` serves with, checked before anything starts.
pub struct ServerPlan {
    server: Server,
    program: PathBuf,
    serve: ServeArgs,
}

impl ServerPlan {
    /// The server's name.
    pub fn name(&self) -> &'static str {
        self.server.name
    }

    /// The `server` `serve` asks for: its program found and its port free, or exit 2.
    pub fn new(server: Server, serve: ServeArgs) -> Result<ServerPlan, Failure> {
        serve.check_port(server, &format!("--{}", server.name))?;
        Ok(ServerPlan {
            server,
            program: sidecar::program(server.program)?,
            serve,
        })
    }

    /// Starts the server with the stack's environment, waits until it serves and prints its
    /// URL. Port 0 is made a free port here, so that a restarted server serves where its
    /// clients look.
    pub fn start(
        mut self,
        env: &[(String, String)],
        log_path: PathBuf,
    ) -> Result<SideServer, Failure> {
        let server = self.server;
        if self.serve.port(server) == 0 {
            let port = std::net::TcpListener::bind((self.serve.bind, 0))
                .and_then(|l| l.local_addr())
                .map_err(|e| Failure::run(format!("no free port for {}: {e}", server.name)))?
                .port();
            self.serve.port = Some(port);
        }
        let ready = ready_file(server);
        let args = self.serve.server_args(server, &ready);
        let sidecar = Sidecar::start(
            server.name,
            server.without,
            (self.program, args),
            RESTART,
            env,
            log_path,
            &ready,
        )?;
        announce(server, &ready);
        Ok(SideServer {
            server,
            sidecar,
            ready,
        })
    }
}

/// A server beside a stack that `mole up` runs.
pub struct SideServer {
    server: Server,
    sidecar: Sidecar,
    /// Where it writes its URL once it serves (again after a restart).
    ready: PathBuf,
}

impl SideServer {
    /// Restarts a server that died, by [`RESTART`]; warns when the run goes on without it.
    pub fn check(&mut self) {
        self.sidecar.check();
    }

    /// Stops the server.
    pub fn stop(self, timeout: Duration) {
        if self.sidecar.stop(timeout) {
            tracing::warn!("{} needed SIGKILL", self.server.name);
        }
        let _ = std::fs::remove_file(&self.ready);
    }
}

/// `mole view --namespace NS` (`mole foxglove …`): serves the running stack in NS until Ctrl-C
/// or the stack ends; `mole view FILE`: a recording, until Ctrl-C.
pub fn view(server: Server, args: &ViewArgs) -> Result<(), Failure> {
    args.serve.check_port(server, "--port")?;
    sidecar::build_process_binaries(&[server.program])?;
    if let Some(file) = &args.file {
        return view_recording(server, file, &args.serve);
    }
    let program = sidecar::program(server.program)?;
    let stack = Attached::to(&args.namespace)?;
    let ready = ready_file(server);
    let mut command = Command::new(program);
    command
        .args(args.serve.server_args(server, &ready))
        .env(env::NAMESPACE, &args.namespace)
        .env(env::MODE, stack.mode.name())
        .stdin(Stdio::null());
    dies_with_the_launcher(&mut command);
    let child = command
        .spawn()
        .map_err(|e| Failure::run(format!("cannot start {}: {e}", server.program)))?;
    let mut announced = false;
    let result = stack.wait(server.name, child, || {
        if !announced && announce(server, &ready) {
            announced = true;
            println!(
                "serving the {} stack in `{}` (Ctrl-C to stop)",
                stack.mode, args.namespace
            );
        }
    });
    let _ = std::fs::remove_file(&ready);
    result.map(drop)
}

/// `mole view FILE`: a recording, no stack and no IPC. The server reads the file before it
/// serves: a file it refuses ends it with exit 2, its reason (naming the file) on stderr.
fn view_recording(server: Server, file: &Path, serve: &ServeArgs) -> Result<(), Failure> {
    if serve.no_controls {
        return Err(Failure::input(
            "--no-controls: a recording has no goals or paces to turn off (only its timeline, \
             which steers nothing)",
        ));
    }
    let program = sidecar::program(server.program)?;
    let interrupted = Arc::new(AtomicBool::new(false));
    let flag = interrupted.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .map_err(|e| Failure::run(format!("cannot install the Ctrl-C handler: {e}")))?;
    let ready = ready_file(server);
    let mut command = Command::new(program);
    command
        .args(serve.server_args(server, &ready))
        .arg("--file")
        .arg(file)
        .stdin(Stdio::null());
    dies_with_the_launcher(&mut command);
    let mut child = command
        .spawn()
        .map_err(|e| Failure::run(format!("cannot start {}: {e}", server.program)))?;
    let (mut announced, mut stopping) = (false, false);
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break Ok(status),
            Ok(None) => {}
            Err(e) => {
                break Err(Failure::run(format!(
                    "cannot wait for {}: {e}",
                    server.name
                )));
            }
        }
        if !announced && announce(server, &ready) {
            announced = true;
            println!("serving the recording {} (Ctrl-C to stop)", file.display());
        }
        if !stopping && interrupted.load(Ordering::SeqCst) {
            stopping = true;
            let pid = nix::unistd::Pid::from_raw(child.id() as i32);
            let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM);
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let _ = std::fs::remove_file(&ready);
    let status = status?;
    match status.code() {
        Some(0) => Ok(()),
        Some(crate::supervisor::EXIT_BAD_INPUT) => Err(Failure::input(format!(
            "{} refused {} (see above)",
            server.name,
            file.display()
        ))),
        _ => Err(Failure::run(format!("{} failed ({status})", server.name))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The launcher starts the Foxglove server its crate declares, where it serves by default.
    #[test]
    fn the_foxglove_server_is_the_one_its_crate_declares() {
        assert_eq!(FOXGLOVE.program, mole_foxglove::FOXGLOVE_PROGRAM);
        assert_eq!(FOXGLOVE.default_port, mole_foxglove::DEFAULT_PORT);
    }
}
