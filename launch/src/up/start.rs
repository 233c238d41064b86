//! Starting: the launcher's own ports, then each process in dependency order, each waited
//! for until its ports exist.

use super::*;

/// Opens the launcher's ports, starts the recorder and the servers (if any) and every process once
/// those it depends on are ready.
pub(super) fn start(
    args: &UpArgs,
    plan: Plan,
    recording: Option<RecordPlan>,
    servers: Vec<ServerPlan>,
) -> Result<Stack<'_>, Failure> {
    let interrupted = Arc::new(AtomicBool::new(false));
    let flag = interrupted.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::SeqCst))
        .map_err(|e| Failure::run(format!("cannot install the Ctrl-C handler: {e}")))?;
    let common = common_args(args, &plan);
    let ports = open_ports(&common, interrupted.clone()).map_err(Failure::run)?;
    let keeper = ResumeKeeper::start(&common, args.out.join(RESUME_DIR)).map_err(Failure::run)?;
    let faults = Injector::new(&ports.ctx, plan.mode, plan.seed)
        .map_err(|e| Failure::run(format!("cannot open stack/faults: {e}")))?;
    let tuner = Tuner::new(
        &ports.ctx,
        plan.launch.settings,
        args.settings_changes.clone(),
    )
    .map_err(|e| Failure::run(format!("cannot open stack/params: {e}")))?;
    let recorder = recording
        .map(|r| r.start(&plan.env, log_of(args, nodes::RECORDER)))
        .transpose()?;
    let servers = servers
        .into_iter()
        .map(|s| {
            let log = log_of(args, s.name());
            s.start(&plan.env, log)
        })
        .collect::<Result<Vec<_>, _>>()?;
    let order = start_order(&plan.launch.processes).map_err(|e| Failure::input(e.to_string()))?;
    let mut stack = Stack {
        args,
        ports,
        keeper,
        supervisor: Supervisor::new(),
        recorder,
        servers,
        faults,
        tuner,
        watch: Watch::new(),
        interrupted,
        progress: progress_bar(plan.ticks, args.quiet),
        started: Instant::now(),
        plan,
    };
    let Plan {
        mode, ticks, seed, ..
    } = stack.plan;
    tracing::info!(namespace = %args.namespace, %mode, ticks, seed, "starting the stack");
    for index in order {
        if let Err(failure) = start_process(&mut stack, index) {
            // The processes already started are killed (the supervisor's drop) before they
            // could clean up: what they leave in shared memory is swept.
            drop(stack);
            cleanup_dead_nodes();
            return Err(failure);
        }
    }
    Ok(stack)
}

/// Starts the process `index` of the launch file once those it depends on are ready.
pub(super) fn start_process(stack: &mut Stack<'_>, index: usize) -> Result<(), Failure> {
    let dependencies = stack.plan.launch.processes[index].depends_on.clone();
    for dependency in &dependencies {
        wait_ready(stack, dependency)?;
    }
    let process = &stack.plan.launch.processes[index];
    let program = stack.plan.programs[&process.role].clone();
    let mut spec = ChildSpec::from_process(process, program, log_of(stack.args, &process.role));
    let own = std::mem::take(&mut spec.env);
    spec.env = stack.plan.env.iter().cloned().chain(own).collect();
    stack
        .supervisor
        .spawn(spec)
        .map_err(|e| Failure::run(e.to_string()))
}

/// The stack's settings as its processes take them.
pub(super) fn common_args(args: &UpArgs, plan: &Plan) -> CommonArgs {
    CommonArgs {
        namespace: args.namespace.clone(),
        mode: plan.mode,
        rate_hz: plan.launch.stack.rate_hz,
        seed: Some(plan.seed),
        takeover: false,
        resume: None,
        settings: None,
    }
}

/// The launcher's node in the stack's namespace and its ports: statistics and the monitor's
/// status in, stack/processes and stack/control out.
pub(super) fn open_ports(
    common: &CommonArgs,
    interrupted: Arc<AtomicBool>,
) -> Result<Ports, String> {
    // The one sweep before the processes start (they do not sweep, see `Context::new`).
    cleanup_dead_nodes();
    let ctx = Context::with_shutdown_flag(nodes::LAUNCHER, common, interrupted)
        .map_err(|e| e.to_string())?;
    let open = || -> Result<_, mole_runtime::RuntimeError> {
        Ok((
            ctx.subscriber(topics::STACK_STATS)?,
            ctx.subscriber(topics::MONITOR_STATUS)?,
            ctx.publisher(topics::STACK_PROCESSES)?,
            ctx.control_server()?,
            ctx.passive_subscriber(topics::OPERATOR_PACE)?,
        ))
    };
    let (stats, status, processes, control, pace) = open().map_err(|e| e.to_string())?;
    Ok(Ports {
        ctx,
        stats,
        status,
        processes,
        control,
        pace,
    })
}

/// Waits until `role` announced its ports (its first `stack/stats`).
pub(super) fn wait_ready(stack: &mut Stack<'_>, role: &str) -> Result<(), Failure> {
    // A bridge waits up to PEER_TIMEOUT for the other half, then ends saying why: its reason,
    // not this timeout, is the news.
    let timeout = if role == nodes::BRIDGE {
        mole_types::link::PEER_TIMEOUT + READY_TIMEOUT
    } else {
        READY_TIMEOUT
    };
    let deadline = Instant::now() + timeout;
    loop {
        let ready = &mut stack.watch.ready;
        stack.ports.stats.drain(|s| {
            ready.insert(read_name(&s.process).into_owned());
        });
        if stack.watch.ready.contains(role) {
            return Ok(());
        }
        for event in poll_supervisor(stack) {
            if let SupervisorEvent::GaveUp { role } = event {
                return Err(gave_up_failure(stack, &role));
            }
        }
        if stack.interrupted.load(Ordering::SeqCst) {
            return Err(Failure::run("interrupted while starting"));
        }
        if Instant::now() > deadline {
            return Err(Failure::run(format!(
                "`{role}` did not become ready within {timeout:?}"
            )));
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

pub(super) fn progress_bar(ticks: u64, quiet: bool) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(ticks);
    if let Ok(style) = ProgressStyle::with_template(
        "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} ticks  {msg}",
    ) {
        bar.set_style(style);
    }
    bar.enable_steady_tick(Duration::from_millis(200));
    bar
}
