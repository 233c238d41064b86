//! `mole doctor`: what makes iceoryx2 stacks fail on a machine, checked, each finding with how to
//! fix it. Exit 0 when all is well, 1 with the list of problems otherwise; `--clean` first
//! removes what dead nodes left (never a live stack's).
//!
//! The checks read the machine through [`Machine`]'s paths, so a test can point them at a
//! directory of its own; what iceoryx2 keeps (its nodes, their doorbells) comes from the runtime
//! ([`mole_runtime::node_census`]).

use crate::Failure;
use clap::Args;
use mole_runtime::NodeCensus;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Shared memory a stack needs free: the default stack reserves 106 MiB in /dev/shm (`du
/// --apparent-size` while it runs; 1.3 MiB of it touched after 1,500 steps), and a process that
/// touches a page of a full tmpfs dies of SIGBUS. Docker's default /dev/shm (64 MiB) is short.
pub const SHARED_MEMORY_NEED: u64 = 128 << 20;
/// Files a process may hold open: measured at most 174 in the default stack (localization) and
/// 238 in a bridge, so the common default of 1,024 is enough and less is a problem.
pub const OPEN_FILES_NEED: u64 = 1024;
/// Clock sources whose `clock_gettime` is a read of a counter, not a system call.
const FAST_CLOCKS: [&str; 5] = [
    "tsc",
    "kvm-clock",
    "arch_sys_counter",
    "hyperv_clocksource_tsc_page",
    "xen",
];

#[derive(Debug, Clone, Args)]
pub struct DoctorArgs {
    /// First remove what dead nodes left (their shared memory, records and doorbells); a live
    /// stack's are never touched.
    #[arg(long)]
    pub clean: bool,
    /// Print the findings as JSON.
    #[arg(long)]
    pub json: bool,
    /// The shared-memory directory to check (a container's, a test's tmpfs).
    #[arg(long, default_value = "/dev/shm", hide = true)]
    pub shm_dir: PathBuf,
}

/// How a check came out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Verdict {
    Ok,
    /// Worth knowing, not a fault.
    Note,
    /// Something that makes stacks fail or mismeasure.
    Problem,
}

/// One check's finding.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Finding {
    pub check: &'static str,
    pub verdict: Verdict,
    pub what: String,
    /// How to fix it (problems and notes).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fix: Option<String>,
}

impl Finding {
    fn ok(check: &'static str, what: String) -> Finding {
        Finding {
            check,
            verdict: Verdict::Ok,
            what,
            fix: None,
        }
    }

    fn problem(check: &'static str, what: String, fix: impl Into<String>) -> Finding {
        Finding {
            check,
            verdict: Verdict::Problem,
            what,
            fix: Some(fix.into()),
        }
    }

    fn note(check: &'static str, what: String, fix: impl Into<String>) -> Finding {
        Finding {
            check,
            verdict: Verdict::Note,
            what,
            fix: Some(fix.into()),
        }
    }
}

/// Where the checks look.
#[derive(Debug, Clone)]
pub struct Machine {
    pub shm: PathBuf,
    /// `/` (container markers), `/proc`, `/sys`, under it.
    pub root: PathBuf,
}

impl Default for Machine {
    fn default() -> Self {
        Machine {
            shm: PathBuf::from("/dev/shm"),
            root: PathBuf::from("/"),
        }
    }
}

/// `mole doctor`.
pub fn doctor(args: &DoctorArgs) -> Result<(), Failure> {
    let cleaned = args.clean.then(mole_runtime::cleanup_dead_nodes);
    let machine = Machine {
        shm: args.shm_dir.clone(),
        ..Machine::default()
    };
    let findings = examine(&machine, &mole_runtime::node_census(), cleaned);
    let problems = findings
        .iter()
        .filter(|f| f.verdict == Verdict::Problem)
        .count();
    if args.json {
        let json = serde_json::json!({ "findings": findings, "problems": problems });
        println!("{json:#}");
    } else {
        for f in &findings {
            let label = match f.verdict {
                Verdict::Ok => "ok     ",
                Verdict::Note => "note   ",
                Verdict::Problem => "PROBLEM",
            };
            println!("{label} {}: {}", f.check, f.what);
            if let Some(fix) = &f.fix {
                println!("        fix: {fix}");
            }
        }
    }
    match problems {
        0 => {
            if !args.json {
                println!("all well");
            }
            Ok(())
        }
        n => Err(Failure::run(format!(
            "{n} problem{} found (listed above)",
            if n == 1 { "" } else { "s" }
        ))),
    }
}

/// Every check, in order; `cleaned`: what `--clean` removed, if it ran.
pub fn examine(machine: &Machine, census: &NodeCensus, cleaned: Option<usize>) -> Vec<Finding> {
    let mut findings = vec![
        shared_memory(&machine.shm),
        iceoryx2_directory(&census.root),
    ];
    findings.extend(leftovers(census, cleaned));
    findings.push(other_users(census, &machine.shm));
    findings.push(container(&machine.root));
    findings.push(clock_source(&machine.root));
    findings.extend(limits());
    findings
}

/// Is the shared-memory directory there, writable, and does it have room?
pub fn shared_memory(shm: &Path) -> Finding {
    const CHECK: &str = "shared memory";
    let dir = shm.display();
    if !shm.is_dir() {
        return Finding::problem(
            CHECK,
            format!("{dir} is not a directory: iceoryx2 keeps every topic's samples there"),
            "mount a tmpfs on it (mount -t tmpfs -o size=1g tmpfs /dev/shm)",
        );
    }
    if nix::unistd::access(shm, nix::unistd::AccessFlags::W_OK).is_err() {
        return Finding::problem(
            CHECK,
            format!("{dir} is not writable by this user"),
            "make it world-writable with the sticky bit, as /dev/shm is: chmod 1777",
        );
    }
    let Ok(stat) = nix::sys::statvfs::statvfs(shm) else {
        return Finding::problem(
            CHECK,
            format!("cannot read {dir}'s size"),
            "check the mount",
        );
    };
    let block = stat.fragment_size();
    let (total, free) = (stat.blocks() * block, stat.blocks_available() * block);
    let sizes = format!("{dir}: {} free of {}", mib(free), mib(total));
    if free < SHARED_MEMORY_NEED {
        return Finding::problem(
            CHECK,
            format!(
                "{sizes}, under the {} a stack needs",
                mib(SHARED_MEMORY_NEED)
            ),
            "give it room: mount -o remount,size=1g /dev/shm, or docker run --shm-size=1g",
        );
    }
    Finding::ok(CHECK, sizes)
}

fn mib(bytes: u64) -> String {
    format!("{:.0} MiB", bytes as f64 / f64::from(1 << 20))
}

/// Can this user make iceoryx2's records in its directory?
pub fn iceoryx2_directory(root: &Path) -> Finding {
    const CHECK: &str = "iceoryx2 directory";
    let dir = root.display();
    let writable = |p: &Path| nix::unistd::access(p, nix::unistd::AccessFlags::W_OK).is_ok();
    if root.is_dir() {
        if writable(root) {
            return Finding::ok(CHECK, format!("{dir} is writable"));
        }
        return Finding::problem(
            CHECK,
            format!("{dir} is not writable by this user: no node can be made"),
            format!(
                "run as the user who made it, or remove it as root (rm -r {dir}) when no stack runs"
            ),
        );
    }
    match root.parent() {
        Some(parent) if writable(parent) => {
            Finding::ok(CHECK, format!("{dir} is made by the first node"))
        }
        _ => Finding::problem(
            CHECK,
            format!("{dir} does not exist and cannot be made by this user"),
            "make it writable for the user that runs the stack",
        ),
    }
}

/// What killed processes left: dead nodes and their doorbells.
pub fn leftovers(census: &NodeCensus, cleaned: Option<usize>) -> Vec<Finding> {
    const CHECK: &str = "left by killed processes";
    let mut findings = Vec::new();
    if let Some(n) = cleaned {
        findings.push(Finding::ok(
            "clean",
            format!(
                "removed {n} leftover{} of dead processes (nodes, their records, doorbells)",
                plural(n)
            ),
        ));
    }
    if let Some(why) = &census.unlisted {
        findings.push(Finding::problem(
            CHECK,
            format!("iceoryx2 cannot list the nodes: {why}"),
            format!("check {}", census.root.display()),
        ));
        return findings;
    }
    let live = format!(
        "{} live node{}",
        census.live.len(),
        plural(census.live.len())
    );
    if census.dead.is_empty() && census.stale_doorbells == 0 {
        findings.push(Finding::ok(CHECK, format!("nothing ({live})")));
        return findings;
    }
    let mut left = Vec::new();
    if !census.dead.is_empty() {
        left.push(format!(
            "{} dead node{} ({})",
            census.dead.len(),
            plural(census.dead.len()),
            census.dead.join(", ")
        ));
    }
    if census.stale_doorbells > 0 {
        let n = census.stale_doorbells;
        left.push(format!("{n} doorbell{} of nodes gone", plural(n)));
    }
    findings.push(Finding::problem(
        CHECK,
        format!("{}; {live}", left.join(", ")),
        "mole doctor --clean (or any `mole up`) removes them; live stacks are not touched",
    ));
    findings
}

fn plural(n: usize) -> &'static str {
    if n == 1 { "" } else { "s" }
}

/// Are there stacks of other users this one cannot see (their nodes, their shared memory)?
pub fn other_users(census: &NodeCensus, shm: &Path) -> Finding {
    const CHECK: &str = "other users' stacks";
    let me = nix::unistd::geteuid();
    let mut owners = std::collections::BTreeSet::new();
    let mut unreadable = 0;
    for entry in std::fs::read_dir(shm).into_iter().flatten().flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if !name.starts_with("iox2_") {
            continue;
        }
        let path = entry.path();
        if nix::unistd::access(&path, nix::unistd::AccessFlags::R_OK).is_ok() {
            continue;
        }
        unreadable += 1;
        if let Ok(meta) = std::fs::metadata(&path) {
            use std::os::unix::fs::MetadataExt;
            let uid = nix::unistd::Uid::from_raw(meta.uid());
            if uid != me {
                let user = nix::unistd::User::from_uid(uid).ok().flatten();
                owners.insert(user.map_or_else(|| format!("uid {uid}"), |u| u.name));
            }
        }
    }
    if unreadable == 0 && census.inaccessible.is_empty() {
        return Finding::ok(CHECK, "none this user cannot read".to_string());
    }
    let owners: Vec<String> = owners.into_iter().collect();
    Finding::problem(
        CHECK,
        format!(
            "{unreadable} shared-memory file{} and {} node{} this user cannot read{}",
            plural(unreadable),
            census.inaccessible.len(),
            plural(census.inaccessible.len()),
            match owners.is_empty() {
                true => String::new(),
                false => format!(" (of {})", owners.join(", ")),
            }
        ),
        "a stack's files belong to the user who runs it: run mole as that user; a dead one's \
         are cleaned by that user or root (mole doctor --clean)",
    )
}

/// In a container, a stack reaches processes in other containers only through a shared IPC
/// namespace and /dev/shm.
pub fn container(root: &Path) -> Finding {
    const CHECK: &str = "container";
    let marker = [".dockerenv", "run/.containerenv"]
        .into_iter()
        .find(|m| root.join(m).exists());
    let environ = std::fs::read(root.join("proc/1/environ")).unwrap_or_default();
    let declared = environ
        .split(|&b| b == 0)
        .find_map(|v| v.strip_prefix(b"container="))
        .map(|v| String::from_utf8_lossy(v).into_owned());
    match (marker, declared) {
        (None, None) => Finding::ok(CHECK, "not in a container".to_string()),
        (marker, declared) => Finding::note(
            CHECK,
            format!(
                "in a container ({})",
                declared.unwrap_or_else(|| marker.unwrap_or_default().to_string())
            ),
            "processes of a stack in other containers reach it only with a shared IPC namespace \
             and /dev/shm: docker run --ipc=host (or --ipc=container:NAME) on each",
        ),
    }
}

/// Is `clock_gettime` a read of a counter (every sample is stamped with it)?
pub fn clock_source(root: &Path) -> Finding {
    const CHECK: &str = "clock source";
    let dir = root.join("sys/devices/system/clocksource/clocksource0");
    let Ok(current) = std::fs::read_to_string(dir.join("current_clocksource")) else {
        return Finding::note(
            CHECK,
            "unknown (no /sys clocksource)".to_string(),
            "nothing to do unless latency figures look high",
        );
    };
    let current = current.trim().to_string();
    if FAST_CLOCKS.contains(&current.as_str()) {
        return Finding::ok(CHECK, current);
    }
    let available = std::fs::read_to_string(dir.join("available_clocksource")).unwrap_or_default();
    let better = available
        .split_whitespace()
        .find(|c| FAST_CLOCKS.contains(c))
        .map_or_else(
            || "a machine (or VM type) with a TSC clock".to_string(),
            |c| format!("echo {c} > {}/current_clocksource (as root)", dir.display()),
        );
    Finding::problem(
        CHECK,
        format!("{current}: every timestamp is a system call, latency figures inflate"),
        better,
    )
}

/// The limits a stack's processes need.
pub fn limits() -> Vec<Finding> {
    use nix::sys::resource::{Resource, getrlimit};
    let mut findings = Vec::new();
    match getrlimit(Resource::RLIMIT_NOFILE) {
        Ok((soft, _)) if soft < OPEN_FILES_NEED => findings.push(Finding::problem(
            "open files",
            format!("{soft} allowed a process, under the {OPEN_FILES_NEED} a mole process may need"),
            format!(
                "ulimit -n {OPEN_FILES_NEED} (systemd: LimitNOFILE=, docker: --ulimit nofile={OPEN_FILES_NEED})"
            ),
        )),
        Ok((soft, _)) => findings.push(Finding::ok("open files", format!("{soft} allowed a process"))),
        Err(e) => findings.push(Finding::note(
            "open files",
            format!("cannot read the limit: {e}"),
            format!("make sure a process may open {OPEN_FILES_NEED} files"),
        )),
    }
    let locked = getrlimit(Resource::RLIMIT_MEMLOCK).map_or_else(
        |e| format!("unknown ({e})"),
        |(soft, _)| format!("{} allowed", mib(soft)),
    );
    findings.push(Finding::ok(
        "locked memory",
        format!("{locked}; mole locks no memory, so any limit does"),
    ));
    findings
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Dir(PathBuf);
    impl Drop for Dir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
    fn dir(name: &str) -> Dir {
        let d = std::env::temp_dir().join(format!("mole-doctor-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        Dir(d)
    }
    fn write(path: PathBuf, text: &str) {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, text).unwrap();
    }

    #[test]
    fn a_slow_clock_source_is_a_problem_with_the_fast_one_to_switch_to() {
        let root = dir("clock");
        let sys = root.0.join("sys/devices/system/clocksource/clocksource0");
        write(sys.join("current_clocksource"), "hpet\n");
        write(sys.join("available_clocksource"), "hpet acpi_pm tsc\n");
        let f = clock_source(&root.0);
        assert_eq!(f.verdict, Verdict::Problem, "{f:?}");
        assert!(f.fix.unwrap().starts_with("echo tsc > "));
        write(sys.join("current_clocksource"), "kvm-clock\n");
        assert_eq!(clock_source(&root.0).verdict, Verdict::Ok);
        assert_eq!(clock_source(&root.0.join("none")).verdict, Verdict::Note);
    }

    #[test]
    fn a_container_is_noticed_by_its_marker_or_its_declaration() {
        let root = dir("container");
        assert_eq!(container(&root.0).verdict, Verdict::Ok);
        write(
            root.0.join("proc/1/environ"),
            "PATH=/bin\0container=podman\0",
        );
        let f = container(&root.0);
        assert_eq!(
            (f.verdict, f.what.as_str()),
            (Verdict::Note, "in a container (podman)")
        );
        assert!(f.fix.unwrap().contains("--ipc=host"));
        std::fs::remove_file(root.0.join("proc/1/environ")).unwrap();
        write(root.0.join(".dockerenv"), "");
        assert_eq!(container(&root.0).what, "in a container (.dockerenv)");
    }

    #[test]
    fn dead_nodes_and_stale_doorbells_are_problems_and_live_ones_are_not() {
        let census = NodeCensus {
            live: vec!["mole/a/world".into()],
            ..NodeCensus::default()
        };
        assert_eq!(leftovers(&census, None)[0].verdict, Verdict::Ok);
        let census = NodeCensus {
            dead: vec!["mole/b/sensing".into()],
            stale_doorbells: 2,
            ..census
        };
        let f = &leftovers(&census, None)[0];
        assert_eq!(f.verdict, Verdict::Problem);
        assert_eq!(
            f.what,
            "1 dead node (mole/b/sensing), 2 doorbells of nodes gone; 1 live node"
        );
    }

    #[test]
    fn shared_memory_that_is_missing_is_a_problem() {
        let f = shared_memory(Path::new("/nonexistent/shm"));
        assert_eq!(f.verdict, Verdict::Problem);
        let d = dir("shm");
        // A directory on the test machine's disk: room enough, writable by the test.
        assert_eq!(
            shared_memory(&d.0).verdict,
            Verdict::Ok,
            "{:?}",
            shared_memory(&d.0)
        );
    }
}
