//! Supervising until the run ends: restarts by policy, hung processes, stalls, progress.

use super::*;

/// Serves `mole swap`, `mole stop` and `mole status`, restarts and reports, shows progress,
/// until the run ends.
pub(super) fn supervise(stack: &mut Stack<'_>) -> RunEnd {
    let mut last_report = Instant::now();
    loop {
        std::thread::sleep(POLL);
        let watch = &mut stack.watch;
        stack.ports.stats.drain(|s| watch.record(s));
        if let Some(end) = serve_control(stack) {
            return end;
        }
        restart_hung(stack);
        stack.faults.release_due();
        if let Some(recorder) = stack.recorder.as_mut() {
            recorder.check();
        }
        for server in &mut stack.servers {
            server.check();
        }
        if last_report.elapsed() >= Duration::from_secs(1) {
            last_report = Instant::now();
            publish_processes(stack);
            stack.tuner.follow(|_| false);
        }
        if let Some(end) = follow_progress(stack) {
            return end;
        }
        if let Some(end) = handle_events(stack) {
            return end;
        }
        if stack.interrupted.load(Ordering::SeqCst) {
            return RunEnd::Interrupted;
        }
        if stack
            .watch
            .world_done_at
            .is_some_and(|t| t.elapsed() > FINISH_TIMEOUT)
        {
            tracing::warn!("the monitor did not finish within {FINISH_TIMEOUT:?}");
            return RunEnd::Finished;
        }
    }
}

/// Counts every hung role and kills it for a restart where its policy restarts it.
pub(super) fn restart_hung(stack: &mut Stack<'_>) {
    for role in hung_roles(
        &stack.plan.launch,
        &stack.supervisor,
        &mut stack.watch.last_heard,
    ) {
        *stack.watch.hangs.entry(role.clone()).or_insert(0) += 1;
        let policy = stack.plan.launch.process(&role).map(|p| p.restart.policy);
        match (policy, stack.supervisor.pid(&role)) {
            (Some(p), Some(pid)) if p != RestartWhen::Never => {
                stack.progress.suspend(|| {
                    tracing::warn!(
                        role,
                        "no statistics for {HANG_TIMEOUT:?}: hung, killing it for a restart"
                    )
                });
                let _ = nix::sys::signal::kill(
                    nix::unistd::Pid::from_raw(pid as i32),
                    nix::sys::signal::Signal::SIGKILL,
                );
            }
            _ => stack
                .progress
                .suspend(|| tracing::warn!(role, "no statistics for {HANG_TIMEOUT:?}: hung")),
        }
    }
}

/// Shows the monitor's progress; the run is over when the monitor says so, or stalled when a
/// lockstep run makes no step for [`STALL_TIMEOUT`].
pub(super) fn follow_progress(stack: &mut Stack<'_>) -> Option<RunEnd> {
    let ticks = stack.plan.ticks;
    stack.ports.status.update();
    if let Some(status) = stack.ports.status.latest() {
        stack.progress.set_position(status.header.tick.min(ticks));
        stack.progress.set_message(format!(
            "coverage {:>5.1}%  loop p50 {:.0} µs p99 {:.0} µs",
            status.coverage * 100.0,
            status.loop_p50_us,
            status.loop_p99_us
        ));
        if status.finished == 1 {
            return Some(RunEnd::Finished);
        }
        if status.header.tick != stack.watch.last_step.0 {
            stack.watch.last_step = (status.header.tick, Instant::now());
        }
    }
    // A run the operator holds (paused, or held after its steps, or started `--paused` with no
    // pace yet) makes no step, and is no stall.
    stack.ports.pace.drain(|_| {});
    let pace = stack.ports.pace.latest();
    if pace.is_some_and(|p| p.op != mole_types::PACE_RUN) || (stack.args.paused && pace.is_none()) {
        stack.watch.last_step.1 = Instant::now();
    }
    let (step, since) = stack.watch.last_step;
    if stack.plan.mode != ClockMode::Lockstep
        || stack.watch.world_done_at.is_some()
        || since.elapsed() <= STALL_TIMEOUT
    {
        return None;
    }
    let steps: Vec<String> = stack
        .watch
        .collector
        .processes()
        .iter()
        .map(|p| format!("{} {}", p.role, p.steps))
        .collect();
    Some(RunEnd::Stalled(Failure::run(format!(
        "the lockstep run stalled: no step for {STALL_TIMEOUT:?} after step {step}; steps \
         handled per process: {} (see the logs in {})",
        steps.join(", "),
        stack.args.out.join("logs").display()
    ))))
}

/// What the supervisor saw; a role it restarts after a crash resumes from the outputs the
/// keeper kept, with the settings in force (those `mole param` changed included).
pub(super) fn poll_supervisor(stack: &mut Stack<'_>) -> Vec<SupervisorEvent> {
    let (keeper, tuner) = (&stack.keeper, &stack.tuner);
    stack.supervisor.poll_with(|role, attempt| {
        let mut env = keeper.before_restart(role, attempt);
        env.push((mole_types::env::SETTINGS.to_owned(), tuner.settings_json()));
        env
    })
}

/// Acts on what the supervisor saw: exits, restarts, roles it gave up on.
pub(super) fn handle_events(stack: &mut Stack<'_>) -> Option<RunEnd> {
    let mut end = None;
    for event in poll_supervisor(stack) {
        let this = match event {
            SupervisorEvent::Exited {
                role,
                status,
                expected,
            } => on_exit(stack, &role, status, expected),
            SupervisorEvent::Restarted { role, attempt } => {
                stack.watch.restarted(&role);
                stack
                    .progress
                    .suspend(|| tracing::warn!(role, attempt, "process restarted"));
                None
            }
            SupervisorEvent::RestartFailed { role, message } => {
                stack
                    .progress
                    .suspend(|| tracing::warn!(role, "restart failed: {message}"));
                None
            }
            SupervisorEvent::GaveUp { role } => Some(gave_up(stack, role)),
        };
        end = end.or(this);
    }
    end
}

/// A process exited: the world's clean end, the monitor's (the run is over), or a failure its
/// restart policy mends or not.
pub(super) fn on_exit(
    stack: &mut Stack<'_>,
    role: &str,
    status: ExitStatus,
    expected: bool,
) -> Option<RunEnd> {
    let graph_role = role.parse::<Role>().ok();
    if status.success() && graph_role == Some(Role::World) {
        stack.watch.world_done_at.get_or_insert_with(Instant::now);
        return None;
    }
    if status.success() && graph_role == Some(Role::Monitor) {
        return Some(RunEnd::Finished);
    }
    if expected {
        return None;
    }
    stack
        .progress
        .suspend(|| tracing::warn!(role, %status, "process exited unexpectedly"));
    // Release what the dead process held before its successor starts.
    cleanup_dead_nodes();
    let restarted = match stack.plan.launch.process(role).map(|p| p.restart.policy) {
        Some(RestartWhen::Always) => true,
        Some(RestartWhen::OnFailure) => !status.success(),
        _ => false,
    };
    // Exit code 2 ends the run through GaveUp; anything else that no policy restarts leaves the
    // stack without the role: the run cannot go on.
    if restarted || status == ExitStatus::Code(EXIT_BAD_INPUT) {
        return None;
    }
    Some(RunEnd::ProcessFailed(Failure::run(format!(
        "`{role}` exited ({status}) and its restart policy does not restart it, so the run \
         cannot go on (see {})",
        log_of(stack.args, role).display()
    ))))
}

/// The supervisor gave up on a role: the run cannot go on.
pub(super) fn gave_up(stack: &mut Stack<'_>, role: String) -> RunEnd {
    let failure = gave_up_failure(stack, &role);
    stack.watch.gave_up.insert(role);
    RunEnd::ProcessFailed(failure)
}

/// Why the supervisor gave up on `role`: its own refusal of its input (exit 2, its error line
/// shown), or failures beyond its restart policy.
pub(super) fn gave_up_failure(stack: &Stack<'_>, role: &str) -> Failure {
    let log = log_of(stack.args, role);
    if stack.supervisor.last_exit(role) == Some(ExitStatus::Code(EXIT_BAD_INPUT)) {
        Failure::input(format!(
            "`{role}` refused its input: {}",
            last_error_line(&log)
        ))
    } else {
        Failure::run(format!(
            "`{role}` kept failing and its restart policy gave up (see {})",
            log.display()
        ))
    }
}

/// `mole status`'s line: where the run is and every role's pid, state and restarts.
pub(super) fn status_line(stack: &Stack<'_>, tick: u64) -> String {
    let (launch, supervisor) = (&stack.plan.launch, &stack.supervisor);
    let restarts = supervisor.restarts();
    let roles: Vec<String> = launch
        .processes
        .iter()
        .map(|p| {
            let state = match supervisor.pid(&p.role) {
                Some(pid) => format!("pid {pid}"),
                None if supervisor.restart_pending(&p.role) => "restarting".to_string(),
                None => "down".to_string(),
            };
            let n = restarts.get(&p.role).copied().unwrap_or(0);
            format!("{} ({state}, {n} restarts)", p.role)
        })
        .collect();
    let of = if stack.plan.ticks == u64::MAX {
        String::new()
    } else {
        format!(" of {}", stack.plan.ticks)
    };
    format!("{}, tick {tick}{of}: {}", stack.plan.mode, roles.join(", "))
}

/// Roles that are running, were heard from, and have been silent for [`HANG_TIMEOUT`]; each is
/// reported once per silence.
pub(super) fn hung_roles(
    launch: &LaunchFile,
    supervisor: &Supervisor,
    last_heard: &mut BTreeMap<String, Instant>,
) -> Vec<String> {
    let mut hung = Vec::new();
    for process in &launch.processes {
        let role = &process.role;
        if let Some(heard) = last_heard.get(role)
            && heard.elapsed() > HANG_TIMEOUT
            && supervisor.is_running(role)
        {
            hung.push(role.clone());
            last_heard.remove(role);
        }
    }
    hung
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A restarted role's hang timer starts over: its old process's last statistics, however
    /// old, no longer count against the new one.
    #[test]
    fn a_restart_starts_the_hang_timer_over() {
        let mut watch = Watch::new();
        let long_ago = Instant::now()
            .checked_sub(2 * HANG_TIMEOUT)
            .expect("the clock runs longer than two hang timeouts");
        watch.last_heard.insert("sensing".into(), long_ago);
        watch.restarted("sensing");
        assert!(watch.last_heard["sensing"] > long_ago);
    }
}
