//! The launcher's keeper: while the stack runs, a thread holds the newest sample of every topic
//! a role resumes from (the graph's `Resume::From`); when such a role dies, the supervisor asks
//! it, before the restart, to write them into a directory the restarted process is pointed at
//! (`MOLE_RESUME`). So a restart after a crash goes on from the role's last output, as a swap
//! does, instead of from the scenario's start.

use mole_runtime::{CommonArgs, Context, SaveRequest};
use mole_types::graph::spec;
use mole_types::topics::WORLD_TRUTH;
use mole_types::{GRAPH, env};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Sender, channel};
use std::thread::JoinHandle;
use std::time::Duration;

/// The keeper's node: `mole/<namespace>/launcher.keeper`.
const KEEPER_NODE: &str = "launcher.keeper";
/// How long a restart waits for the keeper to write what it kept.
const SAVE_TIMEOUT: Duration = Duration::from_secs(1);

pub struct ResumeKeeper {
    requests: Sender<SaveRequest>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    dir: PathBuf,
}

impl ResumeKeeper {
    /// Starts keeping, before any process starts (so no sample goes unseen); the kept samples
    /// are written under `dir` on request.
    pub fn start(common: &CommonArgs, dir: PathBuf) -> Result<ResumeKeeper, String> {
        let mut topics: Vec<&'static str> = GRAPH
            .iter()
            .flat_map(|r| r.resumes_from())
            .copied()
            .collect();
        topics.sort_unstable();
        topics.dedup();
        let (requests, received) = channel();
        let (ready_tx, ready) = channel();
        let stop = Arc::new(AtomicBool::new(false));
        let (common, flag) = (common.clone(), stop.clone());
        let thread = std::thread::Builder::new()
            .name("keeper".into())
            .spawn(move || {
                let keeper = Context::with_shutdown_flag(KEEPER_NODE, &common, flag)
                    .and_then(|ctx| mole_runtime::LastSamples::new(ctx, &topics, WORLD_TRUTH.name));
                match keeper {
                    Ok(keeper) => {
                        let _ = ready_tx.send(Ok(()));
                        if let Err(e) = keeper.serve(received) {
                            tracing::warn!("the keeper stopped: {e}; restarts start afresh");
                        }
                    }
                    Err(e) => _ = ready_tx.send(Err(e.to_string())),
                }
            })
            .map_err(|e| format!("cannot start the keeper thread: {e}"))?;
        match ready.recv() {
            Ok(Ok(())) => Ok(ResumeKeeper {
                requests,
                stop,
                thread: Some(thread),
                dir,
            }),
            Ok(Err(e)) => Err(format!("cannot start the keeper: {e}")),
            Err(_) => Err("the keeper thread ended while starting".into()),
        }
    }

    /// Before `role` restarts (attempt `attempt`): writes the outputs kept for it and returns
    /// the environment that points the restarted process at them; none for a role that
    /// resumes from nothing, or when nothing was kept (it starts afresh, as the log says).
    pub fn before_restart(&self, role: &str, attempt: u32) -> Vec<(String, String)> {
        let topics = spec(role).map(|s| s.resumes_from()).unwrap_or_default();
        if topics.is_empty() {
            return Vec::new();
        }
        let dir = self.dir.join(format!("{role}-{attempt}"));
        let (reply, answer) = channel();
        let request = SaveRequest {
            topics: topics.to_vec(),
            dir: dir.clone(),
            reply,
        };
        let saved = match self.requests.send(request) {
            Ok(()) => answer
                .recv_timeout(SAVE_TIMEOUT)
                .map_err(|e| format!("no answer: {e}"))
                .and_then(|r| r),
            Err(_) => Err("the keeper is gone".into()),
        };
        match saved {
            Ok(0) => {
                tracing::warn!(role, "nothing was kept for the restart: it starts afresh");
                Vec::new()
            }
            Ok(kept) => {
                tracing::info!(role, kept, "the restart resumes from the last outputs kept");
                vec![(env::RESUME.to_owned(), dir.display().to_string())]
            }
            Err(e) => {
                tracing::warn!(role, "cannot keep the last outputs ({e}): it starts afresh");
                Vec::new()
            }
        }
    }

    /// Stops the thread (its node goes with it) and removes what it wrote.
    pub fn stop(mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mole_runtime::{ClockMode, read_resume_file};
    use mole_types::topics::LOCALIZATION_POSE;
    use mole_types::{EstimatorKind, Role};

    /// Before a restart the keeper writes the role's last output and points the restart at it;
    /// a role that resumes from nothing gets no directory; stopping removes what was written.
    #[test]
    fn a_restart_gets_the_last_output_kept_and_the_directory_goes_at_the_end() {
        let namespace = format!("keeper-test-{}", std::process::id());
        let common = CommonArgs::attach(&namespace, ClockMode::Realtime);
        let dir = std::env::temp_dir().join(format!("mole-keeper-test-{}", std::process::id()));
        let keeper = ResumeKeeper::start(&common, dir.clone()).expect("a keeper");
        let flag = Arc::new(AtomicBool::new(false));
        let estimator =
            Context::with_shutdown_flag(Role::Localization.name(), &common, flag).expect("ctx");
        let mut pose = estimator.publisher(LOCALIZATION_POSE).expect("a publisher");
        for tick in 1..=3 {
            pose.publish(tick, 0, |p| {
                (p.x, p.y) = (tick as f64, 2.0);
                p.estimator = EstimatorKind::Ekf.code();
            })
            .expect("published");
        }
        let localization = Role::Localization.name();
        let env = keeper.before_restart(localization, 1);
        assert_eq!(env.len(), 1, "{env:?}");
        assert_eq!(env[0].0, env::RESUME);
        let resumed = PathBuf::from(&env[0].1);
        let kept = read_resume_file(&resumed, LOCALIZATION_POSE)
            .expect("valid")
            .expect("kept");
        assert_eq!((kept.header.tick, kept.x), (3, 3.0), "the newest sample");
        assert!(
            keeper.before_restart(Role::Sensing.name(), 1).is_empty(),
            "sensing resumes from nothing"
        );
        drop((pose, estimator));
        keeper.stop();
        assert!(!dir.exists(), "{} is left", dir.display());
    }
}
