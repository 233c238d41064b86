//! `mole replay FILE`: the recorded run's stack again, from the recording's launch file,
//! scenario, seed and clock mode, with the player (`mole-player`) in place of the roles it
//! replays; `--check` records the replay and compares the live roles' outputs with the
//! recording's, tick by tick.

use crate::Failure;
use crate::settings::StackSettings;
use crate::stand_in::StandIn;
use crate::up::{UpArgs, up};
use clap::Args;
use mole_recorder::cast::{Cast, DEFAULT_REPLACED};
use mole_recorder::tape::for_each_sample;
use mole_recorder::{Window, compare, read_tape};
use mole_runtime::ScheduledChange;
use mole_types::{ClockMode, Message, PARAM_APPLIED, ParamChange, read_name, topics};
use std::path::PathBuf;

/// The grids at every tick in the replay's own recording, so `--check` finds each tick the
/// original kept.
const EVERY_GRID: [&str; 2] = ["mapping/grid=1", "mapping/contact=1"];

#[derive(Debug, Clone, Args)]
pub struct ReplayArgs {
    /// A recording of `mole up --record FILE`.
    pub file: PathBuf,
    /// The roles to play back from the file, comma-separated (any roles of the graph); the
    /// others run live.
    #[arg(long, default_value = DEFAULT_REPLACED)]
    pub replace: String,
    /// Realtime: play this many times as fast as recorded.
    #[arg(long, default_value_t = 1.0)]
    pub rate: f64,
    /// The first tick to play.
    #[arg(long)]
    pub from: Option<u64>,
    /// The last tick to play.
    #[arg(long)]
    pub to: Option<u64>,
    /// Compare the live roles' outputs with the recorded ones, tick by tick: exit 1 naming the
    /// first tick, topic and field that differ.
    #[arg(long)]
    pub check: bool,
    /// Change a setting of the live roles from what the run was recorded with: ROLE.KEY=VALUE
    /// (repeatable; docs/settings.md); with `--check`, where the outputs part from the recording.
    #[arg(long = "set", value_name = "ROLE.KEY=VALUE")]
    pub sets: Vec<String>,
    /// Namespace of the replayed stack.
    #[arg(long, default_value = mole_types::env::DEFAULT_NAMESPACE)]
    pub namespace: String,
    /// Output directory for summary.json, map.png, the logs and the replay's inputs.
    #[arg(long, default_value = "runs/replay")]
    pub out: PathBuf,
    /// No progress bar (logs only).
    #[arg(long)]
    pub quiet: bool,
}

/// `mole replay FILE`: runs the recorded stack with the player in place of the replaced roles;
/// with `--check`, fails (exit 1) on the first output that differs from the recording.
pub fn replay(args: &ReplayArgs) -> Result<(), Failure> {
    let cast = Cast::parse(&args.replace).map_err(|e| Failure::input(format!("--replace: {e}")))?;
    if cast.replaced.is_empty() {
        return Err(Failure::input(
            "--replace: no role named; expected roles of the graph, e.g. world,sensing",
        ));
    }
    if !(args.rate.is_finite() && args.rate > 0.0) {
        return Err(Failure::input(format!(
            "--rate: expected a positive factor, found {}",
            args.rate
        )));
    }
    let file = std::path::absolute(&args.file).unwrap_or_else(|_| args.file.clone());
    let tape = read_tape(&file, &[], Window::ALL).map_err(|e| Failure::input(e.to_string()))?;
    let missing = |what: &str| {
        Failure::input(format!(
            "{}: the recording does not hold its {what} (recorded by `mole record` attached to a \
             running stack?); replay needs a recording of `mole up --record`",
            file.display()
        ))
    };
    let launch_text = tape
        .fact("launch_file")
        .ok_or_else(|| missing("launch file"))?;
    let scenario_text = tape.fact("scenario").ok_or_else(|| missing("scenario"))?;
    let seed: u64 = tape
        .fact("seed")
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| missing("seed"))?;
    let mode: ClockMode = tape
        .fact("clock_mode")
        .and_then(|m| m.parse().ok())
        .ok_or_else(|| missing("clock mode"))?;
    let (first, last) = tape
        .ticks()
        .ok_or_else(|| missing("ticks (no world/truth)"))?;
    let window = Window {
        from: args.from.unwrap_or(first),
        to: args.to.unwrap_or(last).min(last),
    };
    if window.from > window.to {
        return Err(Failure::input(format!(
            "--from {} --to {}: the recording holds ticks {first}..={last}",
            window.from, window.to
        )));
    }
    if args.check && mode != ClockMode::Lockstep {
        return Err(Failure::input(format!(
            "--check: {} is a {mode} recording; only a lockstep run is reproducible step by step",
            file.display()
        )));
    }
    if args.check && window.from > first {
        return Err(Failure::input(format!(
            "--check --from {}: the live roles would start without the ticks before it that made \
             the recorded outputs; check from the start ({first})",
            window.from
        )));
    }

    // The settings the run was recorded with (a recording from before settings: the defaults).
    let settings = match tape.fact("settings") {
        None | Some("unknown") => StackSettings::default(),
        Some(json) => serde_json::from_str::<StackSettings>(json).map_err(|e| {
            Failure::input(format!(
                "{}: its metadata `settings` are not this version's: {e}",
                file.display()
            ))
        })?,
    };
    // The settings changed while it ran, each applied again before the same step.
    let mut settings_changes = Vec::new();
    for_each_sample(&file, &[topics::STACK_PARAMS.name], |sample| {
        let change = (sample.data.len() == size_of::<ParamChange>())
            .then(|| bytemuck::pod_read_unaligned::<ParamChange>(&sample.data));
        if let Some(c) = change.filter(|c| c.validate().is_ok() && c.state == PARAM_APPLIED) {
            settings_changes.push(ScheduledChange {
                tick: c.apply_at,
                role: read_name(&c.role).into_owned(),
                key: read_name(&c.key).into_owned(),
                value: read_name(&c.value).into_owned(),
            });
        }
    })
    .map_err(|e| Failure::input(e.to_string()))?;
    let inputs = args.out.join("replay");
    let written = |name: &str, text: &str| -> Result<PathBuf, Failure> {
        let path = inputs.join(name);
        std::fs::create_dir_all(&inputs)
            .and_then(|()| std::fs::write(&path, text))
            .map_err(|e| Failure::input(format!("cannot write {}: {e}", path.display())))?;
        Ok(path)
    };
    let launch = written("launch.toml", launch_text)?;
    let scenario = written("scenario.toml", scenario_text)?;
    let replayed = inputs.join("replayed.mcap");
    let player_args = vec![
        file.display().to_string(),
        "--replace".to_string(),
        cast.names(),
        "--rate".to_string(),
        args.rate.to_string(),
        "--from".to_string(),
        window.from.to_string(),
        "--to".to_string(),
        window.to.to_string(),
    ];
    let up_args = UpArgs {
        launch: Some(launch),
        scenario: Some(scenario),
        planner: None,
        estimator: None,
        mode: Some(mode),
        ticks: Some(window.to),
        duration: None,
        paused: false,
        goal: None,
        local_planner: None,
        seed: Some(seed),
        namespace: args.namespace.clone(),
        out: args.out.clone(),
        swaps: Vec::new(),
        sets: args.sets.clone(),
        settings: Some(Box::new(settings)),
        settings_changes,
        quiet: args.quiet,
        record: args.check.then(|| replayed.clone()),
        record_every: match args.check {
            true => EVERY_GRID.iter().map(|s| s.to_string()).collect(),
            false => Vec::new(),
        },
        view: Default::default(),
        foxglove: Default::default(),
        stand_in: Some(Box::new(StandIn {
            cast: cast.clone(),
            args: player_args,
        })),
    };
    println!(
        "replaying {} (ticks {}..={}, {mode}): {} from the file, the other roles live",
        file.display(),
        window.from,
        window.to,
        cast.names()
    );
    up(&up_args)?;
    if !args.check {
        return Ok(());
    }
    let compared = cast.compared();
    match compare(&file, &replayed, &compared, window).map_err(|e| Failure::run(e.to_string()))? {
        Ok(done) => {
            println!(
                "check: identical: {} samples of {} over ticks {}..={}",
                done.samples,
                compared.join(", "),
                done.window.from,
                done.window.to
            );
            Ok(())
        }
        Err(difference) => Err(Failure::run(format!("check failed: {difference}"))),
    }
}
