//! The launch file: which processes make up a stack, how to start and restart them.
//!
//! A launch file is TOML with one `[stack]` table and one `[[process]]` table per process; see
//! `launch/stacks/default.toml` for a commented example. Unknown keys are errors, and every error
//! names the file, line, column and field path (`process[2].restart.policy`).
//!
//! Relative data paths such as `stack.scenario` resolve (see [`resolve_data_path`]) against the
//! current directory first, then against the launch file's directory and each of its parents up
//! to and including the workspace root (the first ancestor holding a `Cargo.toml` with a
//! `[workspace]` table, or a `.git`), so `mole up` works from the repository root and from
//! anywhere inside it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::str::FromStr;

use mole_types::graph::nodes::{self, BRIDGE};
use mole_types::link::{self, LinkError};
use mole_types::{ClockMode, EstimatorKind, PlannerKind, Role, UnknownChoice};
use serde::Deserialize;
use toml::Spanned;

use crate::LaunchError;

use crate::settings::StackSettings;
use mole_types::settings::Settings;

/// Where `mole up` looks when no launch file is given.
pub const DEFAULT_LAUNCH_FILE: &str = "launch/stacks/default.toml";

/// A closed choice read from a launch file through its `FromStr`, so a wrong name is refused
/// with the choice's own message (every valid name), located like any other field error.
struct Choice<T>(T);

impl<'de, T: FromStr<Err = UnknownChoice>> Deserialize<'de> for Choice<T> {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let text = String::deserialize(deserializer)?;
        text.parse().map(Choice).map_err(serde::de::Error::custom)
    }
}

/// When a process that exited is started again.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RestartWhen {
    /// Never restart.
    #[default]
    Never,
    /// Restart when the exit code is not 0 or a signal killed the process.
    OnFailure,
    /// Restart after every exit, even a clean one.
    Always,
}

/// Restart policy of one process: `restart = { policy = "on-failure", backoff_ms = 200, max = 5 }`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RestartPolicy {
    /// When to restart (default `never`).
    pub policy: RestartWhen,
    /// Wait before the first restart; doubles with each further restart (default 200 ms).
    pub backoff_ms: u64,
    /// Upper bound of the doubling backoff (default 5000 ms).
    pub max_backoff_ms: u64,
    /// Restarts allowed over the whole run before the launcher gives up (default 5).
    pub max: u32,
    /// A process that ran this long before exiting restarts with the initial backoff again
    /// (default 10000 ms).
    pub stable_after_ms: u64,
}

impl Default for RestartPolicy {
    fn default() -> Self {
        Self {
            policy: RestartWhen::Never,
            backoff_ms: 200,
            max_backoff_ms: 5000,
            max: 5,
            stable_after_ms: 10_000,
        }
    }
}

/// The `[stack]` table: what to run and for how long.
#[derive(Debug, Clone, PartialEq)]
pub struct StackSpec {
    /// Scenario (world) file, as written; resolve it with [`LaunchFile::resolve_path`].
    pub scenario: Option<PathBuf>,
    /// Clock mode.
    pub mode: ClockMode,
    /// World step rate in Hz (realtime mode); > 0.
    pub rate_hz: f64,
    /// Number of world steps to run; `None` with `duration_s` also `None` runs until Ctrl-C.
    pub ticks: Option<u64>,
    /// Run length in simulated seconds; never set together with `ticks`.
    pub duration_s: Option<f64>,
    /// The planner of the planning process.
    pub planner: PlannerKind,
    /// The estimator of the localization process.
    pub estimator: EstimatorKind,
    /// Random seed of the run.
    pub seed: u64,
    /// How long children get between SIGTERM and SIGKILL at shutdown.
    pub shutdown_timeout_ms: u64,
}

impl Default for StackSpec {
    fn default() -> Self {
        Self {
            scenario: None,
            mode: ClockMode::Realtime,
            rate_hz: 100.0,
            ticks: None,
            duration_s: None,
            planner: PlannerKind::RandomWalk,
            estimator: EstimatorKind::Ekf,
            seed: 0,
            shutdown_timeout_ms: 3000,
        }
    }
}

/// One `[[process]]` table.
#[derive(Debug, Clone, PartialEq)]
pub struct ProcessSpec {
    /// The role's name, one of the graph's ([`mole_types::GRAPH`]) or an extra observer
    /// (`observer-<name>`); also names the log file.
    pub role: String,
    /// Program: a bare name (next to `mole`, then `PATH`) or a path.
    pub command: String,
    /// Arguments after the program.
    pub args: Vec<String>,
    /// Extra environment variables.
    pub env: BTreeMap<String, String>,
    /// Roles that must be ready before this process starts.
    pub depends_on: Vec<String>,
    /// What to do when the process exits.
    pub restart: RestartPolicy,
}

/// The `[bridge]` table of one half of a stack split across machines: what the `bridge`
/// process (`mole-bridge`) carries and where it connects.
#[derive(Debug, Clone, PartialEq)]
pub struct BridgeTable {
    /// The namespace of the stack on the other side.
    pub peer_namespace: String,
    /// Topics published here and sent to the peer.
    pub out: Vec<String>,
    /// Topics the peer publishes, published here.
    pub inbound: Vec<String>,
    /// zenoh endpoints to listen on (`tcp/HOST:PORT`, `tls/HOST:PORT`).
    pub listen: Vec<String>,
    /// zenoh endpoints to connect to.
    pub connect: Vec<String>,
    /// TLS files as written; resolve them with [`LaunchFile::resolve_path`].
    pub tls: Option<TlsFiles>,
}

/// `tls = { root_ca = "...", cert = "...", key = "..." }`: PEM files.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TlsFiles {
    /// The certificate authority both sides trust.
    pub root_ca: PathBuf,
    /// This side's certificate.
    pub cert: PathBuf,
    /// This side's private key.
    pub key: PathBuf,
}

impl BridgeTable {
    /// The bridge's command-line arguments for these settings, with the TLS files resolved.
    #[must_use]
    pub fn args(&self, tls: Option<&TlsFiles>) -> Vec<String> {
        let mut args = vec!["--peer-namespace".to_owned(), self.peer_namespace.clone()];
        for (flag, values) in [
            ("--out", &self.out),
            ("--in", &self.inbound),
            ("--listen", &self.listen),
            ("--connect", &self.connect),
        ] {
            for value in values {
                args.extend([flag.to_owned(), value.clone()]);
            }
        }
        if let Some(tls) = tls {
            for (flag, path) in [
                ("--tls-root-ca", &tls.root_ca),
                ("--tls-cert", &tls.cert),
                ("--tls-key", &tls.key),
            ] {
                args.extend([flag.to_owned(), path.display().to_string()]);
            }
        }
        args
    }
}

/// A parsed and validated launch file.
#[derive(Debug, Clone, PartialEq)]
pub struct LaunchFile {
    /// The file it was read from (as given).
    pub path: PathBuf,
    /// The `[stack]` table.
    pub stack: StackSpec,
    /// The `[[process]]` tables in file order.
    pub processes: Vec<ProcessSpec>,
    /// The `[bridge]` table of a half of a split stack.
    pub bridge: Option<BridgeTable>,
    /// Every role's settings: its `[ROLE.…]` tables, checked (docs/settings.md).
    pub settings: StackSettings,
}

impl LaunchFile {
    /// The process with this role.
    #[must_use]
    pub fn process(&self, role: &str) -> Option<&ProcessSpec> {
        self.processes.iter().find(|p| p.role == role)
    }

    /// The roles in file order.
    #[must_use]
    pub fn roles(&self) -> Vec<String> {
        self.processes.iter().map(|p| p.role.clone()).collect()
    }

    /// Resolves a relative data path (e.g. the scenario) by the rule in the module docs,
    /// starting from the current directory.
    pub fn resolve_path(&self, what: &str, path: &Path) -> Result<PathBuf, LaunchError> {
        let cwd = std::env::current_dir().unwrap_or_else(|_| PathBuf::from("."));
        resolve_data_path(what, path, &self.path, &cwd)
    }
}

/// Command-line overrides of the `[stack]` table (`mole up --planner ... --ticks ...`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StackOverrides {
    /// `--scenario`.
    pub scenario: Option<PathBuf>,
    /// `--planner`.
    pub planner: Option<PlannerKind>,
    /// `--estimator`.
    pub estimator: Option<EstimatorKind>,
    /// `--mode`.
    pub mode: Option<ClockMode>,
    /// `--ticks` (clears the file's `duration_s`).
    pub ticks: Option<u64>,
    /// `--duration` in seconds (clears the file's `ticks`).
    pub duration_s: Option<f64>,
    /// `--seed`.
    pub seed: Option<u64>,
}

impl StackOverrides {
    /// Applies the overrides; a run length given on the command line replaces the file's.
    pub fn apply(&self, stack: &mut StackSpec) {
        if let Some(s) = &self.scenario {
            stack.scenario = Some(s.clone());
        }
        if let Some(p) = self.planner {
            stack.planner = p;
        }
        if let Some(e) = self.estimator {
            stack.estimator = e;
        }
        if let Some(m) = self.mode {
            stack.mode = m;
        }
        if let Some(t) = self.ticks {
            stack.ticks = Some(t);
            stack.duration_s = None;
        } else if let Some(d) = self.duration_s {
            stack.duration_s = Some(d);
            stack.ticks = None;
        }
        if let Some(s) = self.seed {
            stack.seed = s;
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Raw (spanned) form, as deserialized.

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLaunchFile {
    #[serde(default)]
    stack: Option<RawStack>,
    #[serde(default)]
    process: Vec<RawProcess>,
    #[serde(default)]
    bridge: Option<Spanned<RawBridge>>,
    #[serde(default)]
    planning: mole_planning::Settings,
    #[serde(default)]
    localization: mole_localization::Settings,
    #[serde(default)]
    mapping: mole_mapping::Settings,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBridge {
    peer_namespace: Spanned<String>,
    #[serde(default)]
    out: Vec<Spanned<String>>,
    #[serde(default, rename = "in")]
    inbound: Vec<Spanned<String>>,
    #[serde(default)]
    listen: Vec<Spanned<String>>,
    #[serde(default)]
    connect: Vec<Spanned<String>>,
    #[serde(default)]
    tls: Option<TlsFiles>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawStack {
    scenario: Option<PathBuf>,
    mode: Option<Choice<ClockMode>>,
    rate_hz: Option<Spanned<f64>>,
    ticks: Option<Spanned<u64>>,
    duration_s: Option<Spanned<f64>>,
    planner: Option<Choice<PlannerKind>>,
    estimator: Option<Choice<EstimatorKind>>,
    seed: Option<u64>,
    shutdown_timeout_ms: Option<u64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawProcess {
    role: Spanned<String>,
    command: Spanned<String>,
    #[serde(default)]
    args: Vec<String>,
    #[serde(default)]
    env: BTreeMap<String, String>,
    #[serde(default)]
    depends_on: Vec<Spanned<String>>,
    #[serde(default)]
    restart: Option<Spanned<RestartPolicy>>,
}

/// Reads, parses and validates a launch file.
pub fn load_launch_file(path: &Path) -> Result<LaunchFile, LaunchError> {
    let text = std::fs::read_to_string(path).map_err(|source| LaunchError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    parse_launch_file(&text, path)
}

/// Parses and validates launch-file text; `path` is only used in error messages and to resolve
/// relative paths later.
pub fn parse_launch_file(text: &str, path: &Path) -> Result<LaunchFile, LaunchError> {
    let invalid = |span: Option<std::ops::Range<usize>>, field: String, message: String| {
        let (line, column) = span.map_or((1, 1), |s| line_column(text, s.start));
        LaunchError::Invalid {
            file: path.to_path_buf(),
            line,
            column,
            field,
            // One line, whatever the parser wrote.
            message: message.split_whitespace().collect::<Vec<_>>().join(" "),
        }
    };

    let de = toml::Deserializer::parse(text)
        .map_err(|e| invalid(e.span(), String::new(), e.message().to_owned()))?;
    let raw: RawLaunchFile = serde_path_to_error::deserialize(de).map_err(|e| {
        let field = field_path(e.path());
        let inner = e.inner();
        invalid(inner.span(), field, inner.message().to_owned())
    })?;

    let stack = match raw.stack {
        Some(s) => validate_stack(s, &invalid)?,
        None => StackSpec::default(),
    };

    let mut processes = Vec::with_capacity(raw.process.len());
    for (i, p) in raw.process.iter().enumerate() {
        let role = p.role.get_ref();
        if let Err(e) = role.parse::<Role>()
            && !is_extra_observer(role)
            && role != nodes::BRIDGE
        {
            return Err(invalid(
                Some(p.role.span()),
                format!("process[{i}].role"),
                format!(
                    "{e}, or observer-<name> (an extra observer), or {BRIDGE} (a split stack's link)"
                ),
            ));
        }
        if let Some(first) = raw.process[..i].iter().find(|q| q.role.get_ref() == role) {
            let (first_line, _) = line_column(text, first.role.span().start);
            return Err(invalid(
                Some(p.role.span()),
                format!("process[{i}].role"),
                format!(
                    "duplicate role `{role}` (first defined on line {first_line}), expected every role once"
                ),
            ));
        }
        if p.command.get_ref().trim().is_empty() {
            return Err(invalid(
                Some(p.command.span()),
                format!("process[{i}].command"),
                "empty command, expected a program name or path".to_owned(),
            ));
        }
        let restart = match &p.restart {
            Some(r) => {
                let policy = *r.get_ref();
                if policy.max_backoff_ms < policy.backoff_ms {
                    return Err(invalid(
                        Some(r.span()),
                        format!("process[{i}].restart.max_backoff_ms"),
                        format!(
                            "max_backoff_ms = {} is below backoff_ms = {}, expected max_backoff_ms >= backoff_ms",
                            policy.max_backoff_ms, policy.backoff_ms
                        ),
                    ));
                }
                policy
            }
            None => RestartPolicy::default(),
        };
        processes.push(ProcessSpec {
            role: role.clone(),
            command: p.command.get_ref().clone(),
            args: p.args.clone(),
            env: p.env.clone(),
            depends_on: p.depends_on.iter().map(|d| d.get_ref().clone()).collect(),
            restart,
        });
    }

    // depends_on names must exist (checked before cycles so a typo is reported as a typo).
    for (i, p) in raw.process.iter().enumerate() {
        for (j, d) in p.depends_on.iter().enumerate() {
            if !processes.iter().any(|q| q.role == *d.get_ref()) {
                let known: Vec<&str> = processes.iter().map(|q| q.role.as_str()).collect();
                return Err(invalid(
                    Some(d.span()),
                    format!("process[{i}].depends_on[{j}]"),
                    format!(
                        "unknown role `{}`, expected one of: {}",
                        d.get_ref(),
                        known.join(", ")
                    ),
                ));
            }
        }
    }

    if let Err(LaunchError::Cycle { cycle }) = order::start_order(&processes) {
        // Point at the entry of cycle[0].depends_on that names cycle[1].
        let from = cycle.first().cloned().unwrap_or_default();
        let to = cycle.get(1).cloned().unwrap_or_default();
        let located = raw.process.iter().enumerate().find_map(|(i, p)| {
            if *p.role.get_ref() != from {
                return None;
            }
            p.depends_on
                .iter()
                .enumerate()
                .find(|(_, d)| *d.get_ref() == to)
                .map(|(j, d)| (i, j, d.span()))
        });
        let (field, span) = match located {
            Some((i, j, span)) => (format!("process[{i}].depends_on[{j}]"), Some(span)),
            None => (String::new(), None),
        };
        return Err(invalid(
            span,
            field,
            format!(
                "dependency cycle {}, expected processes that depend on each other without a circle",
                cycle.join(" -> ")
            ),
        ));
    }

    let bridge = validate_bridge(raw.bridge, &processes, &invalid)?;
    let settings = StackSettings {
        planning: raw.planning,
        localization: raw.localization,
        mapping: raw.mapping,
    };
    settings.check().map_err(|e| {
        invalid(
            crate::settings::located(&e, text),
            e.key.clone(),
            format!("{} is out of bounds: expected {}", e.found, e.expected),
        )
    })?;
    Ok(LaunchFile {
        path: path.to_path_buf(),
        stack,
        processes,
        bridge,
        settings,
    })
}

/// Checks the `[bridge]` table: there exactly when a `bridge` process is, every topic one a
/// bridge may carry, each in one direction, every endpoint well formed, TLS where `tls/` is.
fn validate_bridge(
    raw: Option<Spanned<RawBridge>>,
    processes: &[ProcessSpec],
    invalid: &impl Fn(Option<std::ops::Range<usize>>, String, String) -> LaunchError,
) -> Result<Option<BridgeTable>, LaunchError> {
    let has_process = processes.iter().any(|p| p.role == nodes::BRIDGE);
    let raw = match (raw, has_process) {
        (None, false) => return Ok(None),
        (None, true) => {
            return Err(invalid(
                None,
                "bridge".to_owned(),
                format!(
                    "a `{BRIDGE}` process but no [bridge] table, expected [bridge] with peer_namespace, out, in, listen or connect"
                ),
            ));
        }
        (Some(raw), false) => {
            return Err(invalid(
                Some(raw.span()),
                "bridge".to_owned(),
                format!(
                    "a [bridge] table but no process with role = \"{BRIDGE}\", expected one (command = \"mole-bridge\")"
                ),
            ));
        }
        (Some(raw), true) => raw,
    };
    let span = raw.span();
    let raw = raw.into_inner();
    let located = |field: &str, e: LinkError| {
        invalid(Some(span.clone()), format!("bridge.{field}"), e.to_string())
    };
    if raw.peer_namespace.get_ref().trim().is_empty() {
        return Err(invalid(
            Some(raw.peer_namespace.span()),
            "bridge.peer_namespace".to_owned(),
            LinkError::NoPeer.to_string(),
        ));
    }
    let mut seen_out = Vec::new();
    for (field, list) in [("out", &raw.out), ("in", &raw.inbound)] {
        for (i, topic) in list.iter().enumerate() {
            let name = link::carried_topic(topic.get_ref()).map_err(|e| {
                invalid(
                    Some(topic.span()),
                    format!("bridge.{field}[{i}]"),
                    e.to_string(),
                )
            })?;
            if field == "out" {
                seen_out.push(name);
            } else if seen_out.contains(&name) {
                return Err(invalid(
                    Some(topic.span()),
                    format!("bridge.in[{i}]"),
                    LinkError::BothWays(name.to_owned()).to_string(),
                ));
            }
        }
    }
    for (field, list) in [("listen", &raw.listen), ("connect", &raw.connect)] {
        for (i, endpoint) in list.iter().enumerate() {
            endpoint.get_ref().parse::<link::Endpoint>().map_err(|e| {
                invalid(
                    Some(endpoint.span()),
                    format!("bridge.{field}[{i}]"),
                    e.to_string(),
                )
            })?;
        }
    }
    let texts =
        |list: &[Spanned<String>]| list.iter().map(|s| s.get_ref().clone()).collect::<Vec<_>>();
    let (listen, connect) = (texts(&raw.listen), texts(&raw.connect));
    if let Err(e) = link::endpoints(&listen, &connect, raw.tls.is_some()) {
        let field = match e {
            LinkError::NoEndpoint | LinkError::PortZeroTwice(..) => "listen",
            LinkError::ConnectPortZero(_) => "connect",
            _ => "tls",
        };
        return Err(located(field, e));
    }
    Ok(Some(BridgeTable {
        peer_namespace: raw.peer_namespace.into_inner(),
        out: texts(&raw.out),
        inbound: texts(&raw.inbound),
        listen,
        connect,
        tls: raw.tls,
    }))
}

/// Checks the `[stack]` numbers and fills defaults.
fn validate_stack(
    s: RawStack,
    invalid: &impl Fn(Option<std::ops::Range<usize>>, String, String) -> LaunchError,
) -> Result<StackSpec, LaunchError> {
    let mut stack = StackSpec::default();
    if let Some(r) = &s.rate_hz {
        let hz = *r.get_ref();
        if !(hz.is_finite() && hz > 0.0) {
            return Err(invalid(
                Some(r.span()),
                "stack.rate_hz".to_owned(),
                format!("rate_hz = {hz}, expected a number > 0"),
            ));
        }
        stack.rate_hz = hz;
    }
    if let (Some(_), Some(d)) = (&s.ticks, &s.duration_s) {
        return Err(invalid(
            Some(d.span()),
            "stack.duration_s".to_owned(),
            "both `ticks` and `duration_s` are set, expected at most one of them".to_owned(),
        ));
    }
    if let Some(t) = &s.ticks {
        if *t.get_ref() == 0 {
            return Err(invalid(
                Some(t.span()),
                "stack.ticks".to_owned(),
                "ticks = 0, expected at least 1 (leave ticks and duration_s out to run until Ctrl-C)"
                    .to_owned(),
            ));
        }
        stack.ticks = Some(*t.get_ref());
    }
    if let Some(d) = &s.duration_s {
        let secs = *d.get_ref();
        if !(secs.is_finite() && secs > 0.0) {
            return Err(invalid(
                Some(d.span()),
                "stack.duration_s".to_owned(),
                format!("duration_s = {secs}, expected a number of seconds > 0"),
            ));
        }
        stack.duration_s = Some(secs);
    }
    stack.scenario = s.scenario;
    if let Some(Choice(m)) = s.mode {
        stack.mode = m;
    }
    if let Some(Choice(p)) = s.planner {
        stack.planner = p;
    }
    if let Some(Choice(e)) = s.estimator {
        stack.estimator = e;
    }
    if let Some(seed) = s.seed {
        stack.seed = seed;
    }
    if let Some(t) = s.shutdown_timeout_ms {
        stack.shutdown_timeout_ms = t;
    }
    Ok(stack)
}

/// `process[2].restart.policy`, without the private segments `toml::Spanned` adds.
fn field_path(path: &serde_path_to_error::Path) -> String {
    use serde_path_to_error::Segment;
    let mut out = String::new();
    for segment in path.iter() {
        match segment {
            Segment::Seq { index } => out.push_str(&format!("[{index}]")),
            Segment::Map { key } | Segment::Enum { variant: key } => {
                if key.starts_with("$__") {
                    continue;
                }
                if !out.is_empty() {
                    out.push('.');
                }
                out.push_str(key);
            }
            Segment::Unknown => {
                if !out.is_empty() {
                    out.push('.');
                }
                out.push('?');
            }
        }
    }
    out
}

/// 1-based (line, column in characters) of a byte offset; offsets past the end clamp to the end.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let mut line = 1;
    let mut column = 1;
    for (i, c) in text.char_indices() {
        if i >= offset {
            break;
        }
        if c == '\n' {
            line += 1;
            column = 1;
        } else {
            column += 1;
        }
    }
    (line, column)
}

/// Resolves a data path named in a launch file: absolute paths as they are; relative ones against
/// `cwd` first, then the launch file's directory and its parents up to the workspace root.
pub fn resolve_data_path(
    what: &str,
    path: &Path,
    launch_file: &Path,
    cwd: &Path,
) -> Result<PathBuf, LaunchError> {
    let mut tried = Vec::new();
    if path.is_absolute() {
        if path.exists() {
            return Ok(path.to_path_buf());
        }
        tried.push(path.to_path_buf());
    } else {
        let first = cwd.join(path);
        if first.exists() {
            return Ok(first);
        }
        tried.push(cwd.to_path_buf());
        let launch_dir = cwd.join(launch_file.parent().unwrap_or_else(|| Path::new("")));
        for dir in launch_dir.ancestors() {
            let candidate = dir.join(path);
            if candidate.exists() {
                return Ok(candidate);
            }
            tried.push(dir.to_path_buf());
            if is_workspace_root(dir) {
                break;
            }
        }
    }
    let looked: Vec<String> = tried.iter().map(|p| p.display().to_string()).collect();
    Err(LaunchError::PathNotFound {
        what: what.to_owned(),
        path: path.to_path_buf(),
        looked: looked.join(", "),
    })
}

/// A directory with a `.git` or a `Cargo.toml` that declares a `[workspace]`.
fn is_workspace_root(dir: &Path) -> bool {
    dir.join(".git").exists()
        || std::fs::read_to_string(dir.join("Cargo.toml"))
            .map(|t| t.lines().any(|l| l.trim() == "[workspace]"))
            .unwrap_or(false)
}

/// A role outside the graph that a launch file may add: `observer-<name>` (lower-case letters,
/// digits, `-`), a process that only reads the stack (`mole-observer`, a viewer). Nothing
/// depends on it and it stops last.
fn is_extra_observer(role: &str) -> bool {
    role.strip_prefix("observer-").is_some_and(|name| {
        !name.is_empty()
            && name
                .bytes()
                .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-')
    })
}

pub mod order;
#[cfg(test)]
mod tests;
