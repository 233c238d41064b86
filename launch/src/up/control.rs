//! `stack/control` served while the stack runs: swap, stop, status, faults and settings; and
//! the process table published on `stack/processes`.

use super::*;

/// Answers one `stack/control` request, if one came; a stop request ends the run.
pub(super) fn serve_control(stack: &mut Stack<'_>) -> Option<RunEnd> {
    let call = stack.ports.control.receive()?;
    let request = *call.request();
    match request.op {
        CONTROL_STOP => {
            stack
                .progress
                .suspend(|| tracing::info!("stop requested through stack/control"));
            let text = format!("stopping the stack in namespace `{}`", stack.args.namespace);
            call.respond(|r| write_name(&mut r.text, &text));
            return Some(RunEnd::Stopped);
        }
        CONTROL_STATUS => {
            let tick = stack.ports.status.latest().map_or(0, |s| s.header.tick);
            let line = status_line(stack, tick);
            call.respond(|r| write_name(&mut r.text, &line));
        }
        CONTROL_FAULT => {
            let tick = stack.ports.status.latest().map_or(0, |s| s.header.tick);
            let result = request
                .argv()
                .ok_or_else(|| "the fault's words are not valid UTF-8".to_string())
                .and_then(|words| FaultSpec::from_words(&words).map_err(|e| e.0))
                .and_then(|spec| stack.faults.inject(&spec, &stack.supervisor, tick));
            stack.progress.suspend(|| match &result {
                Ok(line) => tracing::warn!("{line}"),
                Err(why) => tracing::warn!("fault refused: {why}"),
            });
            call.respond(|r| match &result {
                Ok(line) => {
                    r.status = CONTROL_OK;
                    r.tick = tick;
                    write_name(&mut r.text, line);
                }
                Err(why) => {
                    r.status = CONTROL_REFUSED;
                    write_name(&mut r.text, why);
                }
            });
        }
        CONTROL_PARAM => {
            let (status, text) = match request.argv() {
                Some(words) => stack.tuner.handle(&words),
                None => (CONTROL_REFUSED, "the words are not valid UTF-8".to_owned()),
            };
            stack.progress.suspend(|| match status {
                CONTROL_OK if request.argv().is_some_and(|w| w[0] == "set") => {
                    tracing::info!("setting changed: {text}")
                }
                CONTROL_OK => {}
                _ => tracing::warn!("setting not changed: {text}"),
            });
            // Supervision did not watch the steps while the process took it.
            stack.watch.last_step.1 = Instant::now();
            call.respond(|r| {
                r.status = status;
                write_name(&mut r.text, &text);
            });
        }
        _ => {
            let result = swap(stack, &request);
            let line = match &result {
                Ok(report) => {
                    stack.watch.swaps.push(swap_record(report));
                    swap_sentence(report, stack.plan.mode)
                }
                Err(SwapError::Refused(why) | SwapError::Failed(why)) => why.clone(),
            };
            stack.progress.suspend(|| match &result {
                Ok(_) => tracing::info!("{line}"),
                Err(_) => tracing::warn!("swap not done: {line}"),
            });
            call.respond(|r| write_swap_response(r, &result, &line));
            // Supervision did not watch the steps during the swap.
            stack.watch.last_step.1 = Instant::now();
        }
    }
    None
}

/// Replaces a role's process as `request` asks, while the stack runs.
pub(super) fn swap(
    stack: &mut Stack<'_>,
    request: &ControlRequest,
) -> Result<SwapReport, SwapError> {
    let spec = swap_spec(
        &stack.plan.launch,
        &stack.supervisor,
        request,
        &stack.plan.beside,
    )?;
    let watch = &mut stack.watch;
    let mut on_stats = |s: &Stats| watch.record(s);
    hot_swap(
        SwapEnv {
            ctx: &stack.ports.ctx,
            supervisor: &mut stack.supervisor,
            stats_sub: &mut stack.ports.stats,
            on_stats: &mut on_stats,
            mode: stack.plan.mode,
            stop_timeout: Duration::from_millis(stack.plan.launch.stack.shutdown_timeout_ms),
        },
        spec,
    )
}

pub(super) fn swap_record(report: &SwapReport) -> SwapRecord {
    SwapRecord {
        role: report.role.clone(),
        old_pid: report.old_pid,
        pid: report.pid,
        tick: report.tick,
        topic: report.topic.to_owned(),
        gap_ms: report.gap.as_secs_f64() * 1e3,
        gap_ticks: report.gap_ticks,
        median_interval_ms: report.period.as_secs_f64() * 1e3,
        ticks_observed: report.ticks_observed,
        steps_lost: report.steps_lost,
        steps_repeated: report.steps_repeated,
        killed_old: report.killed_old,
        duration_s: report.duration.as_secs_f64(),
    }
}

/// Publishes every role's state and restarts on stack/processes (for `mole top`).
pub(super) fn publish_processes(stack: &mut Stack<'_>) {
    use mole_types::{
        MAX_PROCESSES, PROCESS_EXITED, PROCESS_FAILED, PROCESS_RESTARTING, PROCESS_RUNNING,
        PROCESS_STARTING,
    };
    let (launch, supervisor, gave_up) =
        (&stack.plan.launch, &stack.supervisor, &stack.watch.gave_up);
    let restarts = supervisor.restarts();
    let result = stack
        .ports
        .processes
        .publish(0, mole_runtime::now_ns(), |m| {
            let n = launch.processes.len().min(MAX_PROCESSES);
            m.n_processes = n as u32;
            for (slot, process) in m.processes.iter_mut().zip(&launch.processes).take(n) {
                write_name(&mut slot.role, &process.role);
                slot.pid = supervisor.pid(&process.role).unwrap_or(0);
                slot.state = if gave_up.contains(&process.role) {
                    PROCESS_FAILED
                } else if supervisor.is_running(&process.role) {
                    PROCESS_RUNNING
                } else if supervisor.restart_pending(&process.role) {
                    PROCESS_RESTARTING
                } else if supervisor.last_exit(&process.role).is_some() {
                    PROCESS_EXITED
                } else {
                    PROCESS_STARTING
                };
                slot.restarts = restarts.get(&process.role).copied().unwrap_or(0);
                slot._pad = 0;
            }
        });
    if let Err(e) = result {
        tracing::debug!("cannot publish stack/processes: {e}");
    }
}

/// The child spec of a hot swap: the role's current spec with the requested program,
/// arguments and working directory (a relative program path is taken from that directory).
pub(super) fn swap_spec(
    launch: &LaunchFile,
    supervisor: &Supervisor,
    request: &ControlRequest,
    beside: &Path,
) -> Result<ChildSpec, SwapError> {
    let role = read_name(&request.role).into_owned();
    if launch.process(&role).is_none() {
        return Err(SwapError::Refused(format!(
            "no process has the role `{role}` (known roles: {})",
            launch.roles().join(", ")
        )));
    }
    check_swappable(&role)?;
    let argv = request
        .argv()
        .ok_or_else(|| SwapError::Refused("the command is not valid UTF-8".to_string()))?;
    let Some((program, arguments)) = argv.split_first() else {
        return Err(SwapError::Refused("the command is empty".to_string()));
    };
    let cwd = PathBuf::from(read_name(&request.cwd).into_owned());
    if !cwd.is_absolute() {
        return Err(SwapError::Refused(format!(
            "the working directory `{}` is not an absolute path",
            cwd.display()
        )));
    }
    let program = if program.contains('/') {
        cwd.join(program).display().to_string()
    } else {
        program.clone()
    };
    let program =
        resolve_program(&program, beside).map_err(|e| SwapError::Refused(e.to_string()))?;
    let mut spec = supervisor
        .spec(&role)
        .cloned()
        .ok_or_else(|| SwapError::Refused(format!("`{role}` is not running")))?;
    spec.program = program;
    spec.args = arguments.to_vec();
    spec.cwd = Some(cwd);
    Ok(spec)
}

/// The answer to `mole swap`: its status, what the swap measured, and `line`.
pub(super) fn write_swap_response(
    r: &mut mole_types::ControlResponse,
    result: &Result<SwapReport, SwapError>,
    line: &str,
) {
    match result {
        Ok(report) => {
            r.status = CONTROL_OK;
            r.pid = report.pid;
            r.gap_ns = report.gap.as_nanos() as u64;
            r.period_ns = report.period.as_nanos() as u64;
            r.steps_lost = report.steps_lost;
            r.steps_repeated = report.steps_repeated;
            r.tick = report.tick;
        }
        Err(SwapError::Refused(_)) => r.status = CONTROL_REFUSED,
        Err(SwapError::Failed(_)) => r.status = CONTROL_FAILED,
    }
    write_name(&mut r.text, line);
}

pub(super) fn swap_sentence(report: &SwapReport, mode: ClockMode) -> String {
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let mut line = format!(
        "swapped `{}`: pid {} → {} at tick {}; {} silent for at most {:.1} ms (median interval \
         {:.2} ms) over {} ticks",
        report.role,
        report.old_pid,
        report.pid,
        report.tick,
        report.topic,
        ms(report.gap),
        ms(report.period),
        report.ticks_observed
    );
    if mode == ClockMode::Lockstep {
        line.push_str(&format!(
            "; lockstep: {} steps lost, {} repeated",
            report.steps_lost, report.steps_repeated
        ));
    }
    if report.killed_old {
        line.push_str("; the old process ignored SIGTERM and was killed");
    }
    line.push_str(&format!("; took {:.2} s", report.duration.as_secs_f64()));
    line
}
