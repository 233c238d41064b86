//! `mole up`'s first stage: everything that can be refused is refused here, before any process
//! starts (exit 2): the launch file, the overrides, the swaps, the scenario, the goal, the
//! namespace, the programs and the output directory.

use super::{Failure, UpArgs};
use crate::launch_file::TlsFiles;
use crate::{
    DEFAULT_LAUNCH_FILE, LaunchFile, StackOverrides, StackSpec, apply_swaps, load_launch_file,
    parse_swap, resolve_program,
};
use mole_runtime::live_nodes_in_namespace;
use mole_types::graph::nodes;
use mole_types::{ClockMode, PlannerKind, env};
use mole_world::Scenario;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A stack ready to start: what to run, how, and with which environment.
pub(super) struct Plan {
    pub launch: LaunchFile,
    pub mode: ClockMode,
    /// Steps to run (`u64::MAX`: until Ctrl-C).
    pub ticks: u64,
    pub seed: u64,
    /// The environment every child gets (its launch-file `env` is added to it).
    pub env: Vec<(String, String)>,
    /// The resolved program of each role.
    pub programs: BTreeMap<String, PathBuf>,
    /// The directory of the `mole` binary, where programs are looked for first.
    pub beside: PathBuf,
}

/// Reads, overrides and checks everything; nothing has started when this fails.
pub(super) fn prepare(args: &UpArgs) -> Result<Plan, Failure> {
    let (mut launch, scenario_path, scenario) = load_stack(args)?;
    launch.settings = args
        .settings
        .as_deref()
        .copied()
        .unwrap_or(launch.settings)
        .with_sets(&args.sets)
        .map_err(Failure::input)?;
    give_the_bridge_its_settings(&mut launch)?;
    check_goal(launch.stack.planner, args.goal, &scenario)?;
    if let Some(why) = launch
        .stack
        .planner
        .refuses_sensors(&scenario.sensors, &scenario.name)
    {
        return Err(Failure::input(why));
    }
    // No length at all: run until Ctrl-C.
    let ticks = match (launch.stack.ticks, launch.stack.duration_s) {
        (Some(ticks), _) => ticks,
        (None, Some(d)) => (d / scenario.dt).round().max(1.0) as u64,
        (None, None) => u64::MAX,
    };
    let seed = args.seed.unwrap_or(launch.stack.seed);
    refuse_namespace_in_use(&args.namespace)?;
    let wanted = [
        launch.bridge.is_some().then_some("mole-bridge"),
        args.foxglove.port.is_some().then_some("mole-foxglove"),
    ];
    crate::sidecar::build_process_binaries(&wanted.into_iter().flatten().collect::<Vec<_>>())?;
    let beside = std::env::current_exe()
        .ok()
        .and_then(|p| p.parent().map(Path::to_path_buf))
        .unwrap_or_default();
    let mut programs = BTreeMap::new();
    for process in &launch.processes {
        let program = resolve_program(&process.command, &beside)
            .map_err(|e| Failure::input(e.to_string()))?;
        programs.insert(process.role.clone(), program);
    }
    prepare_out_dir(&args.out)?;
    let mut env = child_env(args, &launch.stack, &scenario_path, ticks, seed);
    env.push((
        env::SETTINGS.to_owned(),
        launch.settings.to_json_with(&args.settings_changes),
    ));
    Ok(Plan {
        mode: launch.stack.mode,
        launch,
        ticks,
        seed,
        env,
        programs,
        beside,
    })
}

/// A split stack's bridge gets its `[bridge]` table as arguments, the TLS files resolved like
/// any data path of the launch file.
fn give_the_bridge_its_settings(launch: &mut LaunchFile) -> Result<(), Failure> {
    let Some(bridge) = &launch.bridge else {
        return Ok(());
    };
    let tls = match &bridge.tls {
        Some(tls) => {
            let resolve = |what: &str, path: &Path| {
                launch
                    .resolve_path(what, path)
                    .map_err(|e| Failure::input(e.to_string()))
            };
            Some(TlsFiles {
                root_ca: resolve("bridge.tls.root_ca", &tls.root_ca)?,
                cert: resolve("bridge.tls.cert", &tls.cert)?,
                key: resolve("bridge.tls.key", &tls.key)?,
            })
        }
        None => None,
    };
    let args = bridge.args(tls.as_ref());
    if let Some(process) = launch
        .processes
        .iter_mut()
        .find(|p| p.role == nodes::BRIDGE)
    {
        process.args.extend(args);
    }
    Ok(())
}

/// The launch file with the command line's overrides and swaps, and its scenario.
fn load_stack(args: &UpArgs) -> Result<(LaunchFile, PathBuf, Scenario), Failure> {
    let launch_path = args.launch.clone().unwrap_or_else(default_launch_file);
    let mut launch = load_launch_file(&launch_path).map_err(|e| Failure::input(e.to_string()))?;
    if let Some(d) = args.duration
        && !(d.is_finite() && d > 0.0)
    {
        return Err(Failure::input(format!(
            "--duration: expected a positive number of seconds, found {d}"
        )));
    }
    if let Some(local) = args.local_planner
        && !local.needs_goal()
    {
        let followers: Vec<&str> = PlannerKind::ALL
            .iter()
            .filter(|p| p.needs_goal())
            .map(|p| p.name())
            .collect();
        return Err(Failure::input(format!(
            "--local-planner {local}: it does not drive to a goal, so it cannot follow a path; \
             expected one of: {}",
            followers.join(", ")
        )));
    }
    StackOverrides {
        scenario: args.scenario.clone(),
        planner: args.planner,
        estimator: args.estimator,
        mode: args.mode,
        ticks: args.ticks,
        duration_s: args.duration,
        ..StackOverrides::default()
    }
    .apply(&mut launch.stack);
    let swaps = args
        .swaps
        .iter()
        .map(|s| parse_swap(s))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| Failure::input(e.to_string()))?;
    apply_swaps(&mut launch, &swaps).map_err(|e| Failure::input(e.to_string()))?;
    let scenario_path = match (&args.scenario, &launch.stack.scenario) {
        // A path given on the command line is taken as the user typed it.
        (Some(path), _) => path.clone(),
        (None, Some(path)) => launch
            .resolve_path("scenario", path)
            .map_err(|e| Failure::input(e.to_string()))?,
        (None, None) => {
            return Err(Failure::input(format!(
                "{}: no scenario: set `stack.scenario` or pass --scenario",
                launch.path.display()
            )));
        }
    };
    let scenario =
        mole_world::load_scenario(&scenario_path).map_err(|e| Failure::input(e.to_string()))?;
    Ok((launch, scenario_path, scenario))
}

/// The goal the run drives to (`--goal`, else the scenario's) must leave room for the robot
/// inside the arena and off every obstacle; a goal-seeking planner must have one.
pub(super) fn check_goal(
    planner: PlannerKind,
    goal: Option<(f64, f64)>,
    scenario: &Scenario,
) -> Result<(), Failure> {
    let Some((x, y)) = goal.or(scenario.goal.map(|g| (g.x, g.y))) else {
        if planner.needs_goal() {
            return Err(Failure::input(format!(
                "--planner {planner} drives to a goal, but the scenario `{}` has none: pass \
                 --goal X,Y",
                scenario.name
            )));
        }
        return Ok(());
    };
    let r = scenario.robot.radius;
    let (w, h) = (scenario.arena_width, scenario.arena_height);
    if !(r..=w - r).contains(&x) || !(r..=h - r).contains(&y) {
        return Err(Failure::input(format!(
            "goal ({x}, {y}) is outside the arena: the robot (radius {r} m) fits where \
             {r} ≤ x ≤ {} and {r} ≤ y ≤ {} in the {w} m × {h} m arena of `{}`",
            w - r,
            h - r,
            scenario.name
        )));
    }
    let inside = scenario.obstacles.iter().find(|o| {
        let half = o.side / 2.0;
        let dx = ((x - o.cx).abs() - half).max(0.0);
        let dy = ((y - o.cy).abs() - half).max(0.0);
        dx.hypot(dy) < r
    });
    if let Some(o) = inside {
        return Err(Failure::input(format!(
            "goal ({x}, {y}) is in an obstacle: the square of side {} m at ({}, {}) in `{}` \
             leaves no room for the robot (radius {r} m) there",
            o.side, o.cx, o.cy, scenario.name
        )));
    }
    Ok(())
}

fn default_launch_file() -> PathBuf {
    let relative = Path::new(DEFAULT_LAUNCH_FILE);
    if relative.exists() {
        return relative.to_path_buf();
    }
    Path::new(env!("CARGO_MANIFEST_DIR")).join("stacks/default.toml")
}

/// Another stack's live processes in the namespace: refused, naming them.
fn refuse_namespace_in_use(namespace: &str) -> Result<(), Failure> {
    let live: Vec<String> = live_nodes_in_namespace(namespace)
        .into_iter()
        .filter(|n| !n.ends_with(&format!("/{}", mole_types::graph::nodes::TOP)))
        .collect();
    if live.is_empty() {
        return Ok(());
    }
    Err(Failure::input(format!(
        "namespace `{namespace}` is in use by {} live process(es) ({}); stop that stack or \
         choose another --namespace",
        live.len(),
        live.join(", ")
    )))
}

/// The environment of every child, named by [`mole_types::env`].
fn child_env(
    args: &UpArgs,
    stack: &StackSpec,
    scenario: &Path,
    ticks: u64,
    seed: u64,
) -> Vec<(String, String)> {
    let absolute = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    let mut vars = vec![
        (env::NAMESPACE, args.namespace.clone()),
        (env::MODE, stack.mode.name().to_owned()),
        (env::RATE_HZ, stack.rate_hz.to_string()),
        (env::SCENARIO, absolute(scenario).display().to_string()),
        (env::TICKS, ticks.to_string()),
        (env::PLANNER, stack.planner.name().to_owned()),
        (env::ESTIMATOR, stack.estimator.name().to_owned()),
        (env::OUT, absolute(&args.out).display().to_string()),
        (env::SEED, seed.to_string()),
    ];
    if let Some((x, y)) = args.goal {
        vars.push((env::GOAL, format!("{x},{y}")));
    }
    if let Some(local) = args.local_planner {
        vars.push((env::LOCAL_PLANNER, local.name().to_owned()));
    }
    if args.paused {
        vars.push((env::PAUSED, "true".to_owned()));
    }
    vars.into_iter()
        .map(|(name, value)| (name.to_owned(), value))
        .collect()
}

fn prepare_out_dir(out: &Path) -> Result<(), Failure> {
    let failed = |e: std::io::Error| {
        Failure::input(format!(
            "cannot use the output directory {}: {e}",
            out.display()
        ))
    };
    std::fs::create_dir_all(out.join("logs")).map_err(failed)?;
    // The bridge's report of where it listens, which a restarted bridge of this run reuses.
    for stale in ["summary.json", "map.png", mole_types::link::LISTENING_FILE] {
        let path = out.join(stale);
        if path.exists() {
            std::fs::remove_file(&path).map_err(failed)?;
        }
    }
    if let Ok(entries) = std::fs::read_dir(out.join("logs")) {
        for entry in entries.flatten() {
            let _ = std::fs::remove_file(entry.path());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use mole_types::Square;

    /// A 10 m arena with one 1 m square at (5, 5) and no goal of its own.
    fn arena() -> Scenario {
        Scenario {
            obstacles: vec![Square::new(5.0, 5.0, 1.0)],
            ..Scenario::default()
        }
    }

    fn refusal(planner: PlannerKind, goal: Option<(f64, f64)>) -> String {
        match check_goal(planner, goal, &arena()) {
            Ok(()) => panic!("{planner} with {goal:?} was accepted"),
            Err(f) => {
                assert_eq!(f.kind, crate::FailureKind::BadInput);
                f.message
            }
        }
    }

    /// A goal outside the arena names the bounds the robot's radius leaves.
    #[test]
    fn a_goal_outside_the_arena_is_refused_naming_the_bounds() {
        let r = arena().robot.radius;
        let msg = refusal(PlannerKind::Dwa, Some((500.0, 500.0)));
        assert!(
            msg.contains("goal (500, 500) is outside the arena"),
            "{msg}"
        );
        assert!(msg.contains(&format!("x ≤ {}", 10.0 - r)), "{msg}");
        // On the wall itself the robot does not fit either.
        let msg = refusal(PlannerKind::Apf, Some((r / 2.0, 5.0)));
        assert!(msg.contains("outside the arena"), "{msg}");
        assert!(check_goal(PlannerKind::Dwa, Some((r, 10.0 - r)), &arena()).is_ok());
    }

    /// A goal in an obstacle, or closer to it than the robot's radius, names the obstacle.
    #[test]
    fn a_goal_in_an_obstacle_is_refused_naming_it() {
        let r = arena().robot.radius;
        let msg = refusal(PlannerKind::Dwa, Some((5.0, 5.0)));
        assert!(msg.contains("side 1 m at (5, 5)"), "{msg}");
        let msg = refusal(PlannerKind::Dwa, Some((5.5 + r / 2.0, 5.0)));
        assert!(msg.contains("in an obstacle"), "{msg}");
        assert!(check_goal(PlannerKind::Dwa, Some((5.5 + r * 1.01, 5.0)), &arena()).is_ok());
    }

    /// A goal-seeking planner needs a goal; an exploring one does not.
    #[test]
    fn a_goal_seeking_planner_without_a_goal_is_refused() {
        for &planner in PlannerKind::ALL {
            let result = check_goal(planner, None, &arena());
            assert_eq!(result.is_err(), planner.needs_goal(), "{planner}");
        }
        let msg = refusal(PlannerKind::Apf, None);
        assert!(msg.contains("--goal"), "{msg}");
    }
}
