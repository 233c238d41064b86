//! The live view: `mole view` (attached to a running stack) and `mole up --view`, which starts it
//! beside the stack; and `mole view FILE`, a recording in the same view, with a timeline.
//!
//! The view is its own process (`mole-view`), an observer of the stack that is none of its roles:
//! a [`Sidecar`], stopped after every role; if it dies the run goes on without it, with a
//! warning. It writes its page's URL into a file once it serves; the launcher prints it as
//! `view: URL`. A recording's view (`mole-view --file FILE`) needs no stack and opens no IPC: the
//! launcher only starts it, prints its URL and stops it at Ctrl-C.

use crate::Failure;
use crate::sidecar::{self, Attached, Sidecar};
use crate::{RestartPolicy, RestartWhen};
use clap::Args;
use mole_types::env;
use mole_view::{DEFAULT_PORT, VIEW_PROGRAM};
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// The view's name in its log file and its supervisor.
const VIEW: &str = mole_types::graph::nodes::VIEW;
/// Beside `mole up` a view that died is started again (the page reconnects by itself), on the
/// same port; after five restarts the run goes on without it.
const RESTART: RestartPolicy = RestartPolicy {
    policy: RestartWhen::OnFailure,
    backoff_ms: 200,
    max_backoff_ms: 5000,
    max: 5,
    stable_after_ms: 10_000,
};

/// Where and how the view serves (`mole view`'s flags; `mole up --view[=PORT]`).
#[derive(Debug, Clone, Args)]
pub struct ServeArgs {
    /// The port to serve the page on (0: any free port).
    #[arg(long, default_value_t = DEFAULT_PORT)]
    pub port: u16,
    /// The address to serve on. Anything but loopback lets anyone who can reach it watch the
    /// run and, unless --no-controls, steer the robot.
    #[arg(long, default_value_t = IpAddr::V4(Ipv4Addr::LOCALHOST))]
    pub bind: IpAddr,
    /// No goals, pauses or steps from the page: it only watches.
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

impl UpViewArgs {
    /// The view to start beside the stack, if --view asks for one.
    pub fn plan(&self) -> Result<Option<ViewPlan>, Failure> {
        let Some(port) = self.port else {
            return Ok(None);
        };
        ViewPlan::new(ServeArgs {
            port: port.unwrap_or(DEFAULT_PORT),
            bind: self.bind.unwrap_or(IpAddr::V4(Ipv4Addr::LOCALHOST)),
            no_controls: self.no_controls,
        })
        .map(Some)
    }
}

impl ServeArgs {
    /// Refuses, before anything starts, a port that something else serves on already (0, any
    /// free port, always works). `flag` is the option that named it.
    fn check_port(&self, flag: &str) -> Result<(), Failure> {
        if self.port == 0 {
            return Ok(());
        }
        let address = SocketAddr::new(self.bind, self.port);
        std::net::TcpListener::bind(address).map(drop).map_err(|e| {
            Failure::input(format!(
                "{flag}={}: cannot serve the view on {address}: {e}; expected a free port (0 \
                 takes any)",
                self.port
            ))
        })
    }

    /// The view's arguments; warns when the page is served beyond this machine.
    fn view_args(&self, ready: &Path) -> Vec<String> {
        if !self.bind.is_loopback() {
            let steer = if self.no_controls {
                "watch the run"
            } else {
                "watch the run and steer the robot (goals, pause, step; --no-controls turns that off)"
            };
            tracing::warn!(
                "the view serves on {}: anyone who can reach it can {steer}",
                self.bind
            );
        }
        let mut args = vec![
            "--port".to_string(),
            self.port.to_string(),
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

/// The file the view writes its URL into, fresh (a stale one removed).
fn ready_file() -> PathBuf {
    let file = std::env::temp_dir().join(format!("mole-view-{}.url", std::process::id()));
    let _ = std::fs::remove_file(&file);
    file
}

/// Reads the URL the view wrote, prints it as `view: URL` and removes the file.
fn announce(ready: &Path) -> bool {
    let Ok(url) = std::fs::read_to_string(ready) else {
        return false;
    };
    let _ = std::fs::remove_file(ready);
    println!("view: {}", url.trim());
    true
}

/// What `mole up --view` serves with, checked before anything starts.
pub struct ViewPlan {
    program: PathBuf,
    serve: ServeArgs,
}

impl ViewPlan {
    /// The view `serve` asks for: its program found and its port free, or exit 2.
    pub fn new(serve: ServeArgs) -> Result<ViewPlan, Failure> {
        serve.check_port("--view")?;
        Ok(ViewPlan {
            program: sidecar::program(VIEW_PROGRAM)?,
            serve,
        })
    }

    /// Starts the view with the stack's environment, waits until it serves and prints its URL.
    /// Port 0 is made a free port here, so that a restarted view serves where the page looks.
    pub fn start(mut self, env: &[(String, String)], log_path: PathBuf) -> Result<View, Failure> {
        if self.serve.port == 0 {
            self.serve.port = std::net::TcpListener::bind((self.serve.bind, 0))
                .and_then(|l| l.local_addr())
                .map_err(|e| Failure::run(format!("no free port for the view: {e}")))?
                .port();
        }
        let ready = ready_file();
        let args = self.serve.view_args(&ready);
        let sidecar = Sidecar::start(
            VIEW,
            "without the view",
            (self.program, args),
            RESTART,
            env,
            log_path,
            &ready,
        )?;
        announce(&ready);
        Ok(View { sidecar, ready })
    }
}

/// The view beside a stack that `mole up` runs.
pub struct View {
    sidecar: Sidecar,
    /// Where it writes its URL once it serves (again after a restart).
    ready: PathBuf,
}

impl View {
    /// Restarts a view that died, by [`RESTART`]; warns when the run goes on without it.
    pub fn check(&mut self) {
        self.sidecar.check();
    }

    /// Stops the view.
    pub fn stop(self, timeout: Duration) {
        if self.sidecar.stop(timeout) {
            tracing::warn!("the view needed SIGKILL");
        }
        let _ = std::fs::remove_file(&self.ready);
    }
}

/// `mole view --namespace NS`: serves the page of the running stack in NS until Ctrl-C or the
/// stack ends; `mole view FILE`: the page of a recording, until Ctrl-C.
pub fn view(args: &ViewArgs) -> Result<(), Failure> {
    if let Some(file) = &args.file {
        return view_recording(file, &args.serve);
    }
    let program = sidecar::program(VIEW_PROGRAM)?;
    let stack = Attached::to(&args.namespace)?;
    let ready = ready_file();
    let child = Command::new(program)
        .args(args.serve.view_args(&ready))
        .env(env::NAMESPACE, &args.namespace)
        .env(env::MODE, stack.mode.name())
        .stdin(Stdio::null())
        .spawn()
        .map_err(|e| Failure::run(format!("cannot start {VIEW_PROGRAM}: {e}")))?;
    let mut announced = false;
    let result = stack.wait(VIEW, child, || {
        if !announced && announce(&ready) {
            announced = true;
            println!(
                "viewing the {} stack in `{}` (Ctrl-C to stop)",
                stack.mode, args.namespace
            );
        }
    });
    let _ = std::fs::remove_file(&ready);
    result.map(drop)
}

/// `mole view FILE`: the view of a recording, no stack and no IPC. The view reads the file before
/// it serves: a file it refuses ends it with exit 2, its reason (naming the file) on stderr.
fn view_recording(file: &Path, serve: &ServeArgs) -> Result<(), Failure> {
    if serve.no_controls {
        return Err(Failure::input(
            "--no-controls: a recording's view has no goals or paces to turn off (only its \
             timeline, which steers nothing)",
        ));
    }
    let program = sidecar::program(VIEW_PROGRAM)?;
    let interrupted = Arc::new(AtomicBool::new(false));
    let flag = interrupted.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .map_err(|e| Failure::run(format!("cannot install the Ctrl-C handler: {e}")))?;
    let ready = ready_file();
    let mut child = Command::new(program)
        .args(serve.view_args(&ready))
        .arg("--file")
        .arg(file)
        .stdin(Stdio::null())
        .spawn()
        .map_err(|e| Failure::run(format!("cannot start {VIEW_PROGRAM}: {e}")))?;
    let (mut announced, mut stopping) = (false, false);
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break Ok(status),
            Ok(None) => {}
            Err(e) => break Err(Failure::run(format!("cannot wait for the view: {e}"))),
        }
        if !announced && announce(&ready) {
            announced = true;
            println!("viewing the recording {} (Ctrl-C to stop)", file.display());
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
            "the view refused {} (see above)",
            file.display()
        ))),
        _ => Err(Failure::run(format!("the view failed ({status})"))),
    }
}
