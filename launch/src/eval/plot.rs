//! `mole eval --plot`: the distributions of a suite's metrics as one PNG, one panel per metric,
//! the suites compared (this run, `--beside` reports, the `--check` baseline) side by side in
//! each panel: every world as a dot, the mean as a bar with its 95% interval.

use super::EvalReport;
use super::metrics::{Kind, WorldMetrics};
use mole_bench::canvas::{register_font, write_png};
use plotters::prelude::*;
use std::path::Path;

/// Panels per row, and each panel's size (px).
const COLUMNS: usize = 4;
const PANEL: (u32, u32) = (330, 250);
/// Height of the title above the panels (px).
const TITLE_HEIGHT: u32 = 44;
/// At most this many suites in one plot, one colour each.
pub const MAX_SUITES: usize = PALETTE.len();
/// One colour per suite, in order (colour-blind safe: Okabe and Ito 2008).
const PALETTE: [RGBColor; 8] = [
    RGBColor(0, 114, 178),
    RGBColor(213, 94, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(230, 159, 0),
    RGBColor(86, 180, 233),
    RGBColor(240, 228, 66),
    RGBColor(0, 0, 0),
];

/// What one panel shows: a metric and, per suite, its worlds' values.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    pub metric: &'static str,
    pub kind: Kind,
    /// Per suite, in the suites' order: each world's value (worlds without one left out).
    pub values: Vec<Vec<f64>>,
}

/// The panels for `suites`: every metric some world of some suite has, in the order the
/// metrics are defined, except `finished` (a failed run has no other value, so it shows as
/// fewer dots everywhere).
pub fn panels(suites: &[&EvalReport]) -> Vec<Panel> {
    let Some(first) = suites.iter().find_map(|s| s.worlds.first()) else {
        return Vec::new();
    };
    first
        .values()
        .into_iter()
        .filter(|(metric, _, _)| *metric != "finished")
        .map(|(metric, _, kind)| Panel {
            metric,
            kind,
            values: suites.iter().map(|s| column(&s.worlds, metric)).collect(),
        })
        .filter(|p| p.values.iter().any(|v| !v.is_empty()))
        .collect()
}

/// Every world's value of `metric`.
fn column(worlds: &[WorldMetrics], metric: &str) -> Vec<f64> {
    worlds
        .iter()
        .filter_map(|w| {
            w.values()
                .into_iter()
                .find(|(name, _, _)| *name == metric)
                .and_then(|(_, v, _)| v)
        })
        .filter(|v| v.is_finite())
        .collect()
}

/// Each suite's name in the plot: what differs between them (the planner, the estimator, the
/// family), else the planner.
pub fn labels(suites: &[&EvalReport]) -> Vec<String> {
    let differs = |f: fn(&EvalReport) -> &str| suites.iter().any(|s| f(s) != f(suites[0]));
    let planner = differs(|s| &s.planner);
    let estimator = differs(|s| &s.estimator);
    let family = differs(|s| &s.family);
    suites
        .iter()
        .map(|s| {
            let mut parts = Vec::new();
            if planner || !(estimator || family) {
                parts.push(s.planner.clone());
            }
            if estimator {
                parts.push(s.estimator.clone());
            }
            if family {
                parts.push(s.family.clone());
            }
            parts.join(" · ")
        })
        .collect()
}

/// The plot's size for `panels` panels.
pub fn plot_size(panels: usize) -> (u32, u32) {
    let rows = panels.div_ceil(COLUMNS).max(1) as u32;
    (PANEL.0 * COLUMNS as u32, TITLE_HEIGHT + PANEL.1 * rows)
}

/// Draws `suites` to `path` as a PNG.
pub fn write_plot(suites: &[&EvalReport], path: &Path) -> Result<(), String> {
    let (size, pixels) = render(suites).map_err(|e| format!("--plot {}: {e}", path.display()))?;
    write_png(path, size, &pixels).map_err(|e| format!("--plot {e}"))
}

/// `suites` drawn into an RGB buffer, and its size.
pub fn render(suites: &[&EvalReport]) -> Result<((u32, u32), Vec<u8>), String> {
    if suites.is_empty() || suites.len() > PALETTE.len() {
        return Err(format!(
            "{} suites to draw, expected 1 to {}",
            suites.len(),
            PALETTE.len()
        ));
    }
    let panels = panels(suites);
    if panels.is_empty() {
        return Err("no world has a metric to draw".into());
    }
    register_font();
    let labels = labels(suites);
    let size = plot_size(panels.len());
    let mut pixels = vec![0u8; (size.0 * size.1 * 3) as usize];
    {
        let failed = |e: &dyn std::fmt::Display| e.to_string();
        let root = BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| failed(&e))?;
        let worlds: Vec<String> = suites.iter().map(|s| s.worlds.len().to_string()).collect();
        let title = format!(
            "mole eval: {} ({} worlds)",
            suites[0].family,
            worlds.join(" / ")
        );
        let root = root
            .titled(&title, ("sans-serif", 22))
            .map_err(|e| failed(&e))?;
        let rows = panels.len().div_ceil(COLUMNS);
        let areas = root.split_evenly((rows, COLUMNS));
        for (panel, area) in panels.iter().zip(&areas) {
            draw_panel(area, panel, &labels).map_err(|e| failed(&e))?;
        }
        root.present().map_err(|e| failed(&e))?;
    }
    Ok((size, pixels))
}

/// One metric: a column per suite, its worlds as dots, its mean as a bar with the 95% interval.
fn draw_panel(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    panel: &Panel,
    labels: &[String],
) -> Result<(), Box<dyn std::error::Error>> {
    let aggregates: Vec<Option<super::metrics::Aggregate>> = panel
        .values
        .iter()
        .map(|v| super::metrics::Aggregate::of(v, panel.kind))
        .collect();
    let top = match panel.kind {
        Kind::Fraction => 1.05,
        Kind::Mean => {
            let highest = panel
                .values
                .iter()
                .flatten()
                .copied()
                .chain(aggregates.iter().flatten().map(|a| a.ci95[1]))
                .fold(0.0, f64::max);
            if highest > 0.0 { highest * 1.08 } else { 1.0 }
        }
    };
    let n = labels.len();
    let mut chart = ChartBuilder::on(area)
        .caption(panel.metric, ("sans-serif", 16))
        .margin(8)
        .x_label_area_size(24)
        .y_label_area_size(56)
        .build_cartesian_2d(-0.5..(n as f64 - 0.5), 0.0..top)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(n.max(2))
        .x_label_formatter(&|x| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < n {
                labels[i as usize].clone()
            } else {
                String::new()
            }
        })
        .y_labels(6)
        .y_label_formatter(&|v| short(*v))
        .label_style(("sans-serif", 12))
        .draw()?;
    for (i, (values, aggregate)) in panel.values.iter().zip(&aggregates).enumerate() {
        let colour = PALETTE[i];
        let x = i as f64;
        // A yes/no per world would be a column of dots at 0 and 1: the bar says it all.
        if panel.kind == Kind::Mean {
            chart.draw_series(
                values
                    .iter()
                    .enumerate()
                    .map(|(k, &v)| Circle::new((x + jitter(k), v), 2, colour.mix(0.55).filled())),
            )?;
        }
        if let Some(a) = aggregate {
            let [lo, hi] = a.ci95;
            let stroke = colour.stroke_width(3);
            chart.draw_series([
                PathElement::new(vec![(x - 0.3, a.mean), (x + 0.3, a.mean)], stroke),
                PathElement::new(vec![(x, lo), (x, hi)], colour.stroke_width(2)),
                PathElement::new(vec![(x - 0.12, lo), (x + 0.12, lo)], colour.stroke_width(2)),
                PathElement::new(vec![(x - 0.12, hi), (x + 0.12, hi)], colour.stroke_width(2)),
            ])?;
        }
    }
    Ok(())
}

/// A world's horizontal offset in its column: spread over ±0.2, the same on every draw.
fn jitter(k: usize) -> f64 {
    // The golden ratio's fractional parts fill the interval evenly, in any number.
    let u = (k as f64 * 0.618_033_988_749_895).fract();
    (u - 0.5) * 0.4
}

/// An axis value in at most five characters.
fn short(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    match v.abs() {
        a if a >= 10_000.0 => format!("{:.0}k", v / 1000.0),
        a if a >= 100.0 => format!("{v:.0}"),
        a if a >= 1.0 => format!("{v:.1}"),
        _ => format!("{v:.2}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;

    fn report(planner: &str, rmse: &[f64]) -> EvalReport {
        let worlds = rmse
            .iter()
            .enumerate()
            .map(|(i, &r)| WorldMetrics {
                world: format!("clutter-{i:04}"),
                success: Some(i % 2 == 0),
                localization_rmse_m: Some(r),
                ..WorldMetrics::default()
            })
            .collect();
        EvalReport {
            family: "clutter".into(),
            parameters: String::new(),
            planner: planner.into(),
            estimator: "default".into(),
            first_seed: 0,
            worlds,
            aggregate: BTreeMap::new(),
            wall_time_s: 1.0,
            jobs: 1,
        }
    }

    /// A panel per metric some world has, in the metrics' order, each with a column per suite;
    /// `finished` and metrics no world has are left out.
    #[test]
    fn a_panel_per_metric_a_column_per_suite() {
        let (a, b) = (report("dwa", &[0.1, 0.2, 0.3]), report("apf", &[0.4]));
        let p = panels(&[&a, &b]);
        let names: Vec<&str> = p.iter().map(|p| p.metric).collect();
        assert_eq!(names, ["success", "localization_rmse_m"]);
        assert_eq!(p[1].values, vec![vec![0.1, 0.2, 0.3], vec![0.4]]);
        assert_eq!(p[0].kind, Kind::Fraction);
        assert_eq!(p[0].values[0], vec![1.0, 0.0, 1.0]);
    }

    /// Suites are named by what differs between them.
    #[test]
    fn suites_are_named_by_what_differs() {
        let (a, mut b) = (report("dwa", &[0.1]), report("apf", &[0.1]));
        assert_eq!(labels(&[&a, &b]), ["dwa", "apf"]);
        b.planner = "dwa".into();
        b.estimator = "pf".into();
        assert_eq!(labels(&[&a, &b]), ["default", "pf"]);
        assert_eq!(labels(&[&a]), ["dwa"]);
    }

    /// The picture has its size, and each suite's colour is in it.
    #[test]
    fn the_plot_draws_every_suite_in_its_colour() {
        let (a, b) = (report("dwa", &[0.1, 0.2, 0.3]), report("apf", &[0.4, 0.5]));
        let (size, pixels) = render(&[&a, &b]).unwrap();
        assert_eq!(size, plot_size(2));
        assert_eq!(pixels.len(), (size.0 * size.1 * 3) as usize);
        for colour in &PALETTE[..2] {
            let found = pixels
                .chunks_exact(3)
                .any(|p| p == [colour.0, colour.1, colour.2]);
            assert!(found, "{colour:?} is not drawn");
        }
        assert!(
            !pixels
                .chunks_exact(3)
                .any(|p| p == [PALETTE[2].0, PALETTE[2].1, PALETTE[2].2]),
            "a third suite's colour is drawn with two suites"
        );
        let empty = report("dwa", &[]);
        assert!(render(&[&empty]).unwrap_err().contains("no world"));
    }
}
