//! How the stack's cost grows (`scripts/cost-growth.sh`, `mole-plot`): the points of each sweep
//! (observers, arena size, particle count) read from `mole bench stack --json` reports, written
//! as one cost.json, and drawn as one PNG per sweep: loop latency p50/p99 and stack CPU against
//! the variable.

use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::path::Path;

/// Width and height of every plot (px).
pub const PLOT_SIZE: (u32, u32) = (900, 500);

/// One measured point of a sweep.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CostPoint {
    /// The variable: observers, arena side (m) or particles.
    pub x: f64,
    /// Realtime loop latency, the world's truth to the command back at the world (µs).
    pub loop_p50_us: f64,
    pub loop_p99_us: f64,
    /// CPU of every process of the stack over the realtime run, summed (% of one core).
    pub cpu_percent: f64,
    /// Steps the realtime run made (a check that it ran).
    pub realtime_ticks: u64,
    /// Lockstep steps per second, when the point was also run in lockstep.
    pub lockstep_steps_per_s: Option<f64>,
    /// The 1-minute load average of the machine when the point ended.
    pub load_average: Option<f64>,
}

/// One variable swept, its points in order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sweep {
    /// `observers`, `grid` or `particles`: also the plot's name (cost-<name>.png).
    pub name: String,
    /// The x axis's label.
    pub axis: String,
    /// Whether the x axis is logarithmic (the particle count).
    pub log_x: bool,
    pub points: Vec<CostPoint>,
}

/// cost.json: every sweep.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CostReport {
    pub sweeps: Vec<Sweep>,
}

/// A report of `mole bench stack --json` lacks what a point needs.
#[derive(Debug, thiserror::Error)]
#[error("{what}: {reason}")]
pub struct PointError {
    pub what: String,
    pub reason: String,
}

/// A point from the realtime report of `mole bench stack --json` and, if run, the lockstep one.
pub fn point_from_reports(
    x: f64,
    realtime: &Value,
    lockstep: Option<&Value>,
    load_average: Option<f64>,
) -> Result<CostPoint, PointError> {
    let number = |report: &Value, pointer: &str| {
        report
            .pointer(pointer)
            .and_then(Value::as_f64)
            .filter(|v| v.is_finite())
            .ok_or_else(|| PointError {
                what: format!("point {x}"),
                reason: format!("the report has no number at {pointer}"),
            })
    };
    let processes = realtime
        .get("processes")
        .and_then(Value::as_array)
        .filter(|p| !p.is_empty())
        .ok_or_else(|| PointError {
            what: format!("point {x}"),
            reason: "the report lists no process".into(),
        })?;
    let cpu_percent = processes
        .iter()
        .map(|p| number(p, "/cpu_percent"))
        .sum::<Result<f64, _>>()?;
    Ok(CostPoint {
        x,
        loop_p50_us: number(realtime, "/loop_latency_us/p50")?,
        loop_p99_us: number(realtime, "/loop_latency_us/p99")?,
        cpu_percent,
        realtime_ticks: number(realtime, "/ticks")? as u64,
        lockstep_steps_per_s: lockstep.map(|r| number(r, "/steps_per_s")).transpose()?,
        load_average,
    })
}

/// Writes `sweep` as a PNG of [`PLOT_SIZE`] to `path`.
pub fn write_plot(sweeps: &[&Sweep], path: &Path) -> Result<(), String> {
    crate::canvas::write_png(path, PLOT_SIZE, &render(sweeps)?)
}

/// `sweeps` drawn into an RGB buffer of [`PLOT_SIZE`], on the axes of the first: the first in
/// full colour, any other beside it in pale colour and named in the legend (the particle filter
/// with KLD-sampling beside it without).
pub fn render(sweeps: &[&Sweep]) -> Result<Vec<u8>, String> {
    crate::canvas::register_font();
    let Some(sweep) = sweeps.first() else {
        return Err("no sweep to draw".into());
    };
    if let Some(empty) = sweeps.iter().find(|s| s.points.is_empty()) {
        return Err(format!("sweep {} has no point", empty.name));
    }
    let xs = sweeps.iter().flat_map(|s| s.points.iter().map(|p| p.x));
    let (lo, hi) = xs.fold((f64::MAX, f64::MIN), |(lo, hi), x| (lo.min(x), hi.max(x)));
    let (width, height) = PLOT_SIZE;
    let mut pixels = vec![0u8; (width * height * 3) as usize];
    if sweep.log_x {
        let range = (lo.max(1.0) / 1.5)..(hi.max(1.0) * 1.5);
        draw(
            sweeps,
            &mut pixels,
            range.clone().log_scale(),
            range.log_scale(),
        )?;
    } else {
        let pad = ((hi - lo) * 0.05).max(0.5);
        let range = (lo - pad)..(hi + pad);
        draw(sweeps, &mut pixels, range.clone(), range)?;
    }
    Ok(pixels)
}

/// Draws the three lines of each sweep on an x axis of either kind.
fn draw<X>(sweeps: &[&Sweep], pixels: &mut [u8], x: X, secondary_x: X) -> Result<(), String>
where
    X: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
{
    let sweep = sweeps[0];
    let failed = |e: &dyn std::fmt::Display| format!("plot {}: {e}", sweep.name);
    let root = BitMapBackend::with_buffer(pixels, PLOT_SIZE).into_drawing_area();
    root.fill(&WHITE).map_err(|e| failed(&e))?;
    let all = || sweeps.iter().flat_map(|s| s.points.iter());
    let latency_max = all()
        .map(|p| p.loop_p99_us.max(p.loop_p50_us))
        .fold(0.0, f64::max)
        * 1.4; // headroom for the legend
    let cpu_max = all().map(|p| p.cpu_percent).fold(0.0, f64::max) * 1.4;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("mole: loop latency and stack CPU vs {}", sweep.name),
            ("sans-serif", 20),
        )
        .margin(12)
        .x_label_area_size(48)
        .y_label_area_size(72)
        .right_y_label_area_size(72)
        .build_cartesian_2d(x, 0.0..latency_max.max(1.0))
        .map_err(|e| failed(&e))?
        .set_secondary_coord(secondary_x, 0.0..cpu_max.max(1.0));
    chart
        .configure_mesh()
        .x_desc(sweep.axis.as_str())
        .y_desc("realtime loop latency at 100 Hz (µs)")
        .x_label_formatter(&|v| format!("{v:.0}"))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 15))
        .draw()
        .map_err(|e| failed(&e))?;
    chart
        .configure_secondary_axes()
        .y_desc("stack CPU (% of one core)")
        .y_label_formatter(&|v| format!("{v:.0}"))
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 15))
        .draw()
        .map_err(|e| failed(&e))?;
    for (i, sweep) in sweeps.iter().enumerate() {
        // The first sweep in full colour, the others paler and named.
        let shade = |c: RGBColor| {
            if i == 0 {
                c
            } else {
                let pale = |v: u8| (v as u16 + (255 - v as u16) / 2) as u8;
                RGBColor(pale(c.0), pale(c.1), pale(c.2))
            }
        };
        let named = |label: &str| {
            if sweeps.len() == 1 {
                label.to_owned()
            } else {
                format!("{label}, {}", sweep.name)
            }
        };
        let p50 = shade(RGBColor(30, 90, 200));
        let p99 = shade(RGBColor(210, 50, 40));
        let cpu = shade(RGBColor(20, 150, 60));
        let line = |f: fn(&CostPoint) -> f64| sweep.points.iter().map(move |p| (p.x, f(p)));
        let dots = |f: fn(&CostPoint) -> f64, color: RGBColor| {
            line(f).map(move |xy| Circle::new(xy, 4, color.filled()))
        };
        let legend = |color: RGBColor| {
            move |(x, y): (i32, i32)| {
                PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(3))
            }
        };
        chart
            .draw_series(LineSeries::new(
                line(|p| p.loop_p50_us),
                p50.stroke_width(2),
            ))
            .map_err(|e| failed(&e))?
            .label(named("loop latency p50"))
            .legend(legend(p50));
        chart
            .draw_series(dots(|p| p.loop_p50_us, p50))
            .map_err(|e| failed(&e))?;
        chart
            .draw_series(LineSeries::new(
                line(|p| p.loop_p99_us),
                p99.stroke_width(2),
            ))
            .map_err(|e| failed(&e))?
            .label(named("loop latency p99"))
            .legend(legend(p99));
        chart
            .draw_series(dots(|p| p.loop_p99_us, p99))
            .map_err(|e| failed(&e))?;
        chart
            .draw_secondary_series(LineSeries::new(
                line(|p| p.cpu_percent),
                cpu.stroke_width(2),
            ))
            .map_err(|e| failed(&e))?
            .label(named("stack CPU (right axis)"))
            .legend(legend(cpu));
        chart
            .draw_secondary_series(dots(|p| p.cpu_percent, cpu))
            .map_err(|e| failed(&e))?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .label_font(("sans-serif", 14))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(|e| failed(&e))?;
    root.present().map_err(|e| failed(&e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn report(p50: f64, p99: f64, cpus: &[f64]) -> Value {
        let processes: Vec<Value> = cpus.iter().map(|c| json!({"cpu_percent": c})).collect();
        json!({
            "ticks": 1500,
            "steps_per_s": 99.5,
            "loop_latency_us": {"p50": p50, "p99": p99, "max": 9000.0},
            "processes": processes,
        })
    }

    /// A point takes the loop's p50 and p99, the sum of every process's CPU and the lockstep
    /// rate from the two reports.
    #[test]
    fn a_point_sums_the_processes_cpu() {
        let lockstep = json!({"steps_per_s": 4200.0});
        let p = point_from_reports(
            4.0,
            &report(410.0, 3900.0, &[1.5, 2.0, 0.5]),
            Some(&lockstep),
            Some(1.2),
        )
        .unwrap();
        assert_eq!(
            p,
            CostPoint {
                x: 4.0,
                loop_p50_us: 410.0,
                loop_p99_us: 3900.0,
                cpu_percent: 4.0,
                realtime_ticks: 1500,
                lockstep_steps_per_s: Some(4200.0),
                load_average: Some(1.2),
            }
        );
    }

    /// A report without a latency or without processes is refused, naming what is missing.
    #[test]
    fn a_report_without_its_numbers_is_refused() {
        let mut no_latency = report(410.0, 3900.0, &[1.0]);
        no_latency["loop_latency_us"]["p99"] = Value::Null;
        let e = point_from_reports(1.0, &no_latency, None, None).unwrap_err();
        assert!(e.to_string().contains("/loop_latency_us/p99"), "{e}");
        let e = point_from_reports(1.0, &report(1.0, 2.0, &[]), None, None).unwrap_err();
        assert!(e.to_string().contains("no process"), "{e}");
    }

    /// Each sweep's plot is a PNG of PLOT_SIZE that decodes, with the three series' colours in
    /// it, on a linear and on a logarithmic x axis.
    #[test]
    fn plots_decode_at_their_size_with_every_series() {
        /// The test's directory, removed even when an assertion fails.
        struct Dir(std::path::PathBuf);
        impl Drop for Dir {
            fn drop(&mut self) {
                let _ = std::fs::remove_dir_all(&self.0);
            }
        }
        let dir = Dir(std::env::temp_dir().join(format!("mole-cost-plot-{}", std::process::id())));
        std::fs::create_dir_all(&dir.0).unwrap();
        for (log_x, xs) in [(false, [0.0, 1.0, 4.0, 8.0]), (true, [1e3, 1e4, 3e4, 1e5])] {
            let sweep = Sweep {
                name: "observers".into(),
                axis: "observers reading every topic".into(),
                log_x,
                points: xs
                    .iter()
                    .enumerate()
                    .map(|(i, &x)| {
                        let r = report(
                            300.0 + 50.0 * i as f64,
                            2000.0 + 400.0 * i as f64,
                            &[3.0 + i as f64],
                        );
                        point_from_reports(x, &r, None, None).unwrap()
                    })
                    .collect(),
            };
            let path = dir.0.join(format!("plot-{log_x}.png"));
            // Beside it, the same sweep 20 % cheaper, drawn pale.
            let mut cheaper = sweep.clone();
            cheaper.name = "cheaper".into();
            for p in &mut cheaper.points {
                p.cpu_percent *= 0.8;
                p.loop_p50_us *= 0.8;
            }
            write_plot(&[&sweep, &cheaper], &path).unwrap();
            let decoder =
                png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&path).unwrap()));
            let mut reader = decoder.read_info().unwrap();
            let mut pixels = vec![0; reader.output_buffer_size().unwrap()];
            let info = reader.next_frame(&mut pixels).unwrap();
            assert_eq!((info.width, info.height), PLOT_SIZE);
            assert_eq!(info.color_type, png::ColorType::Rgb);
            let has = |rgb: [u8; 3]| pixels.chunks(3).any(|p| p == rgb);
            assert!(
                has([30, 90, 200]) && has([210, 50, 40]) && has([20, 150, 60]),
                "log {log_x}"
            );
            // The sweep beside it, in pale colours.
            assert!(has([142, 172, 227]) && has([137, 202, 157]), "log {log_x}");
            // Text is drawn: dark anti-aliased grey pixels besides pure black lines.
            assert!(
                pixels
                    .chunks(3)
                    .filter(|p| p[0] == p[1] && p[1] == p[2] && p[0] > 0 && p[0] < 200)
                    .count()
                    > 500
            );
        }
    }

    /// A sweep with no point has no plot.
    #[test]
    fn an_empty_sweep_is_refused() {
        let sweep = Sweep {
            name: "grid".into(),
            axis: "arena side (m)".into(),
            log_x: false,
            points: Vec::new(),
        };
        assert!(render(&[&sweep]).unwrap_err().contains("no point"));
    }
}
