//! Finishing: stop in the graph's order, wait for the monitor's files, complete summary.json.

use super::*;

/// Stops the stack in the graph's order, releases the launcher's ports, completes summary.json.
pub(super) fn finish(stack: Stack<'_>, end: RunEnd) -> Result<RunOutcome, Failure> {
    let Stack {
        args,
        plan,
        ports,
        keeper,
        mut supervisor,
        recorder,
        servers,
        faults,
        tuner,
        mut watch,
        progress,
        started,
        ..
    } = stack;
    progress.finish_and_clear();
    // Before the stop: a process a fault holds stopped could not take its SIGTERM.
    let faults = faults.finish();
    let mut tuner = tuner;
    tuner.follow(|_| false);
    let settings_changes = tuner.changes;
    let stopping: Vec<String> = stop_order(&plan.launch.processes)
        .into_iter()
        .map(|i| plan.launch.processes[i].role.clone())
        .collect();
    let timeout = Duration::from_millis(plan.launch.stack.shutdown_timeout_ms);
    let killed = supervisor.shutdown(&stopping, timeout);
    if !killed.is_empty() {
        tracing::warn!(?killed, "needed SIGKILL");
    }
    // Each process's last statistics, published as it ended: every step and all its CPU.
    let mut ports = ports;
    ports.stats.drain(|s| watch.record(s));
    // After every role: the recorder reads their last samples before it finishes its file.
    if let Some(recorder) = recorder {
        recorder.stop(timeout);
    }
    for server in servers {
        server.stop(timeout);
    }
    drop(ports);
    keeper.stop();
    cleanup_dead_nodes();

    let summary_path = args.out.join("summary.json");
    let exit_reason = end.exit_reason();
    let failure = end.into_failure();
    if plan.launch.process(Role::Monitor.name()).is_none() {
        // A half of a split stack without the monitor: the summary is written on the other side.
        if let Some(failure) = failure {
            return Err(failure);
        }
        println!(
            "{} ({}): this half has no monitor; the run's summary is written where the monitor runs \
             (logs: {})",
            exit_reason.unwrap_or("finished"),
            plan.mode,
            args.out.join("logs").display()
        );
        return Ok(RunOutcome {
            summary_path,
            summary: None,
            stats: watch.collector,
        });
    }
    if !summary_path.exists()
        && let Some(failure) = failure
    {
        // The run failed before the monitor could write anything: the failure is the news.
        return Err(failure);
    }
    let mut summary = read_summary(&summary_path).map_err(|e| {
        Failure::run(format!(
            "the monitor wrote no readable summary at {}: {e}",
            summary_path.display()
        ))
    })?;
    summary.restarts = supervisor.restarts();
    summary.hangs = watch.hangs;
    summary.swaps = watch.swaps;
    summary.faults = faults;
    if let Some(reason) = exit_reason {
        summary.exit_reason = reason.to_owned();
    }
    summary.launcher_wall_time_s = Some(started.elapsed().as_secs_f64());
    summary.settings = serde_json::to_value(plan.launch.settings).unwrap_or_default();
    summary.settings_changes = serde_json::to_value(&settings_changes).unwrap_or_default();
    write_summary(&summary, &summary_path)
        .map_err(|e| Failure::run(format!("cannot complete {}: {e}", summary_path.display())))?;
    report(&summary, &args.out);
    match failure {
        Some(failure) => Err(failure),
        None => Ok(RunOutcome {
            summary_path,
            summary: Some(summary),
            stats: watch.collector,
        }),
    }
}

/// The line `mole up` prints at the end.
pub(super) fn report(s: &Summary, out: &Path) {
    let p50 = s
        .loop_latency_us
        .p50
        .map_or("-".to_owned(), |v| format!("{v:.0}"));
    println!(
        "{} ticks ({}), coverage {:.1}%, loop latency p50 {p50} µs, max penetration {} m, exit: {} → {}",
        s.ticks,
        s.mode,
        s.coverage * 100.0,
        s.max_penetration_m,
        s.exit_reason,
        out.display()
    );
}
