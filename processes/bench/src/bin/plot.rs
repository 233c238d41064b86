//! `mole-plot`: gathers the points `scripts/cost-growth.sh` measured into one cost.json and draws
//! one plot per sweep (cost-<sweep>.png): loop latency p50/p99 and stack CPU against the
//! variable; the particle filter with KLD-sampling (`particles-kld`) is drawn beside the one
//! without, in cost-particles.png.
//!
//! The points file has one line per point, tab-separated: the sweep (`observers`, `grid`,
//! `particles`, `particles-kld`), the variable's value, the realtime report of `mole bench stack --json`, the
//! lockstep one or `-`, and the 1-minute load average when the point ended or `-`. With
//! `--redraw cost.json` it draws the plots of a cost.json again, measuring nothing.

use clap::Parser;
use mole_bench::cost::{CostReport, Sweep, point_from_reports, write_plot};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The sweeps, in order: name, x axis label, logarithmic x axis.
const SWEEPS: [(&str, &str, bool); 4] = [
    (
        "observers",
        "observers reading every topic (mole-observer)",
        false,
    ),
    (
        "grid",
        "arena side (m); 0.05 m cells up to 512² cells (25.6 m), then the grid stops growing",
        false,
    ),
    (
        "particles",
        "particle filter's particles (log scale; the message carries at most 16,384)",
        true,
    ),
    (
        "particles-kld",
        "particle filter's most particles, KLD-sampling (log scale)",
        true,
    ),
];

/// A sweep drawn in another's plot instead of its own: (sweep, the plot's sweep).
const DRAWN_BESIDE: [(&str, &str); 1] = [("particles-kld", "particles")];

#[derive(Debug, Parser)]
#[command(
    name = "mole-plot",
    about = "cost.json and the cost plots from measured points"
)]
struct Args {
    /// The points file (see the program's documentation).
    #[arg(long, required_unless_present = "redraw", requires = "json")]
    points: Option<PathBuf>,
    /// Where cost.json goes.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Draw the plots of this cost.json instead.
    #[arg(long, conflicts_with = "points")]
    redraw: Option<PathBuf>,
    /// Where the plots go (cost-observers.png, cost-grid.png, cost-particles.png).
    #[arg(long)]
    img_dir: PathBuf,
}

fn main() -> ExitCode {
    match run(&Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("mole-plot: {e}");
            ExitCode::from(2)
        }
    }
}

fn run(args: &Args) -> Result<(), String> {
    let report = match (&args.redraw, &args.points) {
        (Some(cost), _) => {
            serde_json::from_str(&read(cost)?).map_err(|e| format!("{}: {e}", cost.display()))?
        }
        (None, Some(points)) => gather(points)?,
        (None, None) => return Err("give --points or --redraw".into()),
    };
    if let Some(json) = &args.json {
        let text = serde_json::to_string_pretty(&report).map_err(|e| e.to_string())?;
        std::fs::write(json, text + "\n").map_err(|e| format!("{}: {e}", json.display()))?;
    }
    for sweep in &report.sweeps {
        if DRAWN_BESIDE.iter().any(|&(s, _)| s == sweep.name) {
            continue;
        }
        let beside = report.sweeps.iter().filter(|other| {
            DRAWN_BESIDE
                .iter()
                .any(|&(s, plot)| s == other.name && plot == sweep.name)
        });
        let sweeps: Vec<&Sweep> = std::iter::once(sweep).chain(beside).collect();
        let path = args.img_dir.join(format!("cost-{}.png", sweep.name));
        write_plot(&sweeps, &path)?;
        println!("{}", path.display());
    }
    Ok(())
}

/// The report of the points in the file `points`.
fn gather(points: &Path) -> Result<CostReport, String> {
    let text = read(points)?;
    let mut report = CostReport {
        sweeps: SWEEPS
            .iter()
            .map(|&(name, axis, log_x)| Sweep {
                name: name.into(),
                axis: axis.into(),
                log_x,
                points: Vec::new(),
            })
            .collect(),
    };
    for (n, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let at = format!("{}:{}", points.display(), n + 1);
        let fields: Vec<&str> = line.split('\t').collect();
        let [sweep, x, realtime, lockstep, load] = fields[..] else {
            return Err(format!(
                "{at}: expected 5 tab-separated fields, found {}",
                fields.len()
            ));
        };
        let sweep = report
            .sweeps
            .iter_mut()
            .find(|s| s.name == sweep)
            .ok_or_else(|| format!("{at}: unknown sweep `{sweep}`"))?;
        let x: f64 = x
            .parse()
            .map_err(|_| format!("{at}: `{x}` is not a number"))?;
        let realtime = json(Path::new(realtime))?;
        let lockstep = match lockstep {
            "-" => None,
            path => Some(json(Path::new(path))?),
        };
        let load = load.parse().ok();
        let point = point_from_reports(x, &realtime, lockstep.as_ref(), load)
            .map_err(|e| format!("{at}: {e}"))?;
        sweep.points.push(point);
    }
    report.sweeps.retain(|s| !s.points.is_empty());
    if report.sweeps.is_empty() {
        return Err(format!("{}: no point", points.display()));
    }
    Ok(report)
}

fn read(path: &Path) -> Result<String, String> {
    std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))
}

fn json(path: &Path) -> Result<serde_json::Value, String> {
    serde_json::from_str(&read(path)?).map_err(|e| format!("{}: {e}", path.display()))
}
