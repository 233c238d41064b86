//! `mole doctor` on conditions the tests create: a process killed with SIGKILL leaves a dead
//! node that `--clean` removes while a live one stays; a low open-files limit; a small
//! shared-memory mount, another user's stack files and a read-only iceoryx2 directory (as root).

use mole_integration_tests::*;
use std::os::unix::process::CommandExt as _;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

fn doctor(args: &[&str]) -> Output {
    doctor_with(args, |_| {})
}

/// `mole doctor ARGS`, the command first shaped by `shape` (a limit, another user).
fn doctor_with(args: &[&str], shape: impl FnOnce(&mut Command)) -> Output {
    let mut command = Command::new(bin_dir().join("mole"));
    command.arg("doctor").args(args).stdin(Stdio::null());
    shape(&mut command);
    command.output().expect("run mole doctor")
}

fn text(output: &Output) -> String {
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// The line of `check` in the doctor's report.
fn line<'a>(report: &'a str, check: &str) -> &'a str {
    report
        .lines()
        .find(|l| {
            l.split_once(' ')
                .is_some_and(|(_, rest)| rest.trim_start().starts_with(check))
        })
        .unwrap_or_else(|| panic!("no `{check}` line in:\n{report}"))
}

/// A sensing process of its own in `namespace`, once its node is up.
struct Role(Child);
impl Role {
    fn start(namespace: &str) -> Role {
        let child = Command::new(bin_dir().join("mole-sensing"))
            .args(["--namespace", namespace, "--mode", "lockstep"])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("start mole-sensing");
        let deadline = Instant::now() + Duration::from_secs(20);
        while mole_runtime::live_nodes_in_namespace(namespace).is_empty() {
            assert!(Instant::now() < deadline, "mole-sensing made no node");
            std::thread::sleep(Duration::from_millis(20));
        }
        Role(child)
    }
}
impl Drop for Role {
    /// Stops it as Ctrl-C would, so its node goes with it; SIGKILL only if it does not.
    fn drop(&mut self) {
        if let Ok(Some(_)) = self.0.try_wait() {
            return;
        }
        signal(self.0.id(), nix::sys::signal::Signal::SIGTERM);
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            if let Ok(Some(_)) = self.0.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A process killed with SIGKILL leaves its node dead: the doctor names it (exit 1) and says
/// how to clean it; `--clean` removes it and the doctor no longer finds it, while the node of
/// a process that still runs is untouched.
#[test]
fn a_killed_process_leaves_a_dead_node_that_clean_removes_and_a_live_one_stays() {
    let _serial = serial();
    let files_before = shm_files();
    let (dead_ns, live_ns) = (
        unique_namespace("doctor-dead"),
        unique_namespace("doctor-live"),
    );
    let live = Role::start(&live_ns);
    let mut killed = Role::start(&dead_ns);
    killed.0.kill().expect("SIGKILL");
    killed.0.wait().expect("reaped");
    // What a process killed a moment ago left may still be in the making for all another one
    // can tell; the cleaning takes it once it is older than that.
    std::thread::sleep(mole_runtime::HALF_MADE_AGE + Duration::from_millis(500));
    let dead_node = format!("mole/{dead_ns}/sensing");

    let before = doctor(&[]);
    let report = text(&before);
    assert_eq!(before.status.code(), Some(1), "{report}");
    let left = line(&report, "left by killed processes");
    assert!(left.starts_with("PROBLEM"), "{report}");
    assert!(left.contains(&dead_node), "{report}");
    assert!(report.contains("fix: mole doctor --clean"), "{report}");
    let stderr = String::from_utf8_lossy(&before.stderr);
    assert!(stderr.contains("problem"), "{stderr}");

    let cleaning = doctor(&["--clean"]);
    let report = text(&cleaning);
    assert!(
        line(&report, "clean").contains("leftovers of dead processes"),
        "{report}"
    );
    assert!(!report.contains(&dead_node), "{report}");
    let after = text(&doctor(&["--json"]));
    let json: serde_json::Value = serde_json::from_str(&after).expect("JSON");
    let findings = json["findings"].as_array().expect("findings");
    assert!(
        findings
            .iter()
            .all(|f| !f["what"].as_str().unwrap_or_default().contains(&dead_node))
    );
    assert_eq!(
        mole_runtime::live_nodes_in_namespace(&live_ns),
        [format!("mole/{live_ns}/sensing")],
        "the live node was touched"
    );
    drop(live);
    let left: Vec<String> = shm_files()
        .into_iter()
        .filter(|f| !files_before.contains(f))
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// Fewer open files than a mole process may need is a problem with its fix.
#[test]
fn a_low_open_files_limit_is_a_problem() {
    let output = doctor_with(&[], |command| {
        // SAFETY: setrlimit is async-signal-safe; nothing else runs between fork and exec.
        unsafe {
            command.pre_exec(|| {
                nix::sys::resource::setrlimit(nix::sys::resource::Resource::RLIMIT_NOFILE, 64, 64)
                    .map_err(std::io::Error::from)
            });
        }
    });
    let report = text(&output);
    assert_eq!(output.status.code(), Some(1), "{report}");
    let files = line(&report, "open files");
    assert!(
        files.starts_with("PROBLEM") && files.contains("64 allowed"),
        "{report}"
    );
    assert!(report.contains("ulimit -n 1024"), "{report}");
}

/// As root: a shared-memory mount too small for a stack, another user's stack files this user
/// cannot read, and an iceoryx2 directory this user cannot write are each a problem.
#[test]
fn a_small_shared_memory_another_users_files_and_a_closed_directory_are_problems() {
    let test = "a_small_shared_memory_another_users_files_and_a_closed_directory_are_problems";
    if !nix::unistd::getuid().is_root() {
        return skip(
            test,
            "mounting a tmpfs and running as another user need root",
        );
    }
    let _serial = serial();
    let small = std::env::temp_dir().join(format!("mole-doctor-shm-{}", std::process::id()));
    std::fs::create_dir_all(&small).expect("a mount point");
    let mounted = Command::new("mount")
        .args(["-t", "tmpfs", "-o", "size=16m", "tmpfs"])
        .arg(&small)
        .status()
        .expect("run mount");
    if !mounted.success() {
        let _ = std::fs::remove_dir(&small);
        return skip(
            test,
            "mount -t tmpfs failed (a container without CAP_SYS_ADMIN)",
        );
    }
    let output = doctor(&["--shm-dir", small.to_str().expect("a path")]);
    let _ = Command::new("umount").arg(&small).status();
    let _ = std::fs::remove_dir(&small);
    let report = text(&output);
    let shm = line(&report, "shared memory");
    assert!(
        shm.starts_with("PROBLEM") && shm.contains("16 MiB"),
        "{report}"
    );
    assert!(report.contains("--shm-size"), "{report}");

    // Root's stack file, private as every stack's is, seen by nobody.
    let file = format!("/dev/shm/iox2_mole_doctor_test_{}", std::process::id());
    std::fs::write(&file, b"").expect("a file");
    use std::os::unix::fs::PermissionsExt as _;
    std::fs::set_permissions(&file, std::fs::Permissions::from_mode(0o600)).expect("chmod");
    let root_dir = std::path::Path::new("/tmp/iceoryx2");
    std::fs::create_dir_all(root_dir).expect("iceoryx2's directory");
    let nobody = 65534;
    let output = doctor_with(&[], |c| {
        c.uid(nobody).gid(nobody).current_dir("/");
    });
    let _ = std::fs::remove_file(&file);
    let report = text(&output);
    assert_eq!(output.status.code(), Some(1), "{report}");
    let others = line(&report, "other users' stacks");
    assert!(
        others.starts_with("PROBLEM") && others.contains("(of root)"),
        "{report}"
    );
    let dir = line(&report, "iceoryx2 directory");
    assert!(
        dir.starts_with("PROBLEM") && dir.contains("not writable"),
        "{report}"
    );
}
