//! The report as a text table and as a hand-written SVG plot (p50 vs payload size, log-log).

use crate::{BenchError, IpcReport, Summary, Transport, ZenohReport};
use std::fmt::Write as _;
use std::path::Path;

/// `64 B`, `16 KiB`, `4 MiB`.
pub fn size_label(size: usize) -> String {
    if size >= 1 << 20 && size.is_multiple_of(1 << 20) {
        format!("{} MiB", size >> 20)
    } else if size >= 1 << 10 && size.is_multiple_of(1 << 10) {
        format!("{} KiB", size >> 10)
    } else {
        format!("{size} B")
    }
}

fn rate_label(per_s: f64) -> String {
    if per_s >= 1e9 {
        format!("{:.2} G", per_s / 1e9)
    } else if per_s >= 1e6 {
        format!("{:.2} M", per_s / 1e6)
    } else if per_s >= 1e3 {
        format!("{:.1} k", per_s / 1e3)
    } else {
        format!("{per_s:.0} ")
    }
}

/// `flat out` or `100 Hz`.
fn pacing_label(rate_hz: Option<f64>) -> String {
    rate_hz.map_or("flat out".to_string(), |hz| format!("{hz} Hz"))
}

fn summary_cells(s: &Summary) -> String {
    format!(
        "{:>7} {:>10.2} {:>10.2} {:>10.2} {:>10.2}",
        s.count, s.p50_us, s.p99_us, s.p999_us, s.max_us
    )
}

/// The whole report as a plain-text table.
pub fn format_table(report: &IpcReport) -> String {
    let mut t = String::new();
    let head = format!(
        "{:>7} {:>10} {:>10} {:>10} {:>10}",
        "n", "p50 µs", "p99 µs", "p99.9 µs", "max µs"
    );
    let _ = writeln!(
        t,
        "mole bench ipc: {} CPUs, one-way latency send → receive, ping-pong paced",
        report.cpus
    );
    let _ = writeln!(
        t,
        "\n{:<13} {:<9} {:>8} {head} {:>13} {:>11}",
        "transport", "wake", "size", "hand-off p50", "fill p50"
    );
    for p in &report.latency {
        let _ = writeln!(
            t,
            "{:<13} {:<9} {:>8} {} {:>13.2} {:>11.2}",
            p.transport.as_str(),
            p.wake.as_str(),
            size_label(p.size),
            summary_cells(&p.latency),
            p.handoff.p50_us,
            p.fill.p50_us
        );
    }
    let _ = writeln!(
        t,
        "\nwake-up floor: a pipe between two processes, write → the blocking read returns\n\
         {:<13} {:<9} {:>9} {:>8} {head}",
        "transport", "placement", "pacing", "CPUs"
    );
    for p in &report.floor {
        let cpus = p
            .cpus
            .map_or("unpinned".to_string(), |[a, b]| format!("{a} → {b}"));
        let _ = write!(
            t,
            "{:<13} {:<9} {:>9} {:>8} {}",
            p.transport.as_str(),
            p.placement.as_str(),
            pacing_label(p.rate_hz),
            cpus,
            summary_cells(&p.latency)
        );
        match &p.unpinned {
            Some(why) => {
                let _ = writeln!(t, "  ({why})");
            }
            None => t.push('\n'),
        }
    }
    let _ = writeln!(
        t,
        "\nthroughput, one publisher flat out\n{:<13} {:>8} {:>12} {:>12} {:>12} {:>12}",
        "transport", "size", "sent msg/s", "recv msg/s", "recv B/s", "received"
    );
    for p in &report.throughput {
        let _ = writeln!(
            t,
            "{:<13} {:>8} {:>12} {:>12} {:>12} {:>12}",
            p.transport.as_str(),
            size_label(p.size),
            rate_label(p.sent_per_s),
            rate_label(p.received_per_s),
            rate_label(p.bytes_per_s),
            p.received
        );
    }
    if let Some(zenoh) = &report.zenoh {
        zenoh_rows(&mut t, report, zenoh, &head);
    }
    let _ = writeln!(
        t,
        "\nfan-out, latency to the last subscriber (event wake-up)\n{:<13} {:>5} {:>8} {head}",
        "transport", "subs", "size"
    );
    for p in &report.fanout {
        let _ = writeln!(
            t,
            "{:<13} {:>5} {:>8} {}",
            p.transport.as_str(),
            p.subscribers,
            size_label(p.size),
            summary_cells(&p.latency)
        );
    }
    let _ = writeln!(
        t,
        "\nfive-hop event chain, driver → 5 probes → driver\n{:<13} {:>9} {head}",
        "transport", "pacing"
    );
    for p in &report.chain {
        let _ = writeln!(
            t,
            "{:<13} {:>9} {}",
            p.transport.as_str(),
            pacing_label(p.rate_hz),
            summary_cells(&p.latency)
        );
    }
    let _ = writeln!(t, "\nratios");
    for r in &report.ratios {
        let _ = writeln!(t, "  {:<60} {:>8.2}", r.what, r.value);
    }
    t
}

/// zenoh's rows: latency by size beside the TCP socket's p50, throughput, and how it ran.
fn zenoh_rows(t: &mut String, report: &IpcReport, zenoh: &ZenohReport, head: &str) {
    let _ = writeln!(
        t,
        "\nzenoh over loopback TCP, one-way latency (round trip / 2)\n{:<13} {:>8} {head} {:>13}",
        "transport", "size", "÷ tcp p50"
    );
    for p in &zenoh.latency {
        let tcp = report
            .latency
            .iter()
            .find(|l| l.transport == Transport::Tcp && l.size == p.size)
            .filter(|l| l.latency.p50_us > 0.0)
            .map_or("-".to_string(), |l| {
                format!("{:.2}", p.latency.p50_us / l.latency.p50_us)
            });
        let _ = writeln!(
            t,
            "{:<13} {:>8} {} {:>13}",
            "zenoh tcp",
            size_label(p.size),
            summary_cells(&p.latency),
            tcp
        );
    }
    let r = &zenoh.throughput;
    let _ = writeln!(
        t,
        "{:<13} {:>8} {:>12} {:>12} {:>12} {:>12}\n{:<13} {:>8} {:>12} {:>12} {:>12.1} {:>12}",
        "throughput",
        "size",
        "sent msg/s",
        "recv msg/s",
        "recv MB/s",
        "received",
        "zenoh tcp",
        size_label(r.size),
        rate_label(r.sent_per_s),
        rate_label(r.received_per_s),
        r.megabytes_per_s,
        r.received
    );
    let _ = writeln!(t, "note: {}", zenoh.setup);
}

/// Prints [`format_table`] to standard output (for `mole bench ipc`).
pub fn print_table(report: &IpcReport) {
    use std::io::Write as _;
    let _ = std::io::stdout()
        .lock()
        .write_all(format_table(report).as_bytes());
}

const WIDTH: f64 = 820.0;
const HEIGHT: f64 = 520.0;
const LEFT: f64 = 80.0;
const RIGHT: f64 = 30.0;
const TOP: f64 = 50.0;
const BOTTOM: f64 = 60.0;
const COLORS: [&str; 8] = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
];
/// The floor's dashed lines: none of the series' colours.
const FLOOR_COLORS: [&str; 4] = ["#000000", "#17becf", "#bcbd22", "#8c8c8c"];

/// The latency plot: p50 (µs) against payload size (bytes), both axes logarithmic, one line per
/// transport and wake-up mode, the pipe wake-up floor's p50s as dashed horizontal lines (they
/// do not depend on the payload), with a legend.
pub fn render_svg(report: &IpcReport) -> String {
    // One series per (transport, wake), in the report's order.
    let mut series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for p in &report.latency {
        let name = format!("{} ({})", p.transport.as_str(), p.wake.as_str());
        if !(p.latency.p50_us > 0.0 && p.latency.p50_us.is_finite()) {
            continue;
        }
        let point = (p.size as f64, p.latency.p50_us);
        match series.iter_mut().find(|(n, _)| *n == name) {
            Some((_, points)) => points.push(point),
            None => series.push((name, vec![point])),
        }
    }
    for (_, points) in &mut series {
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    let floors: Vec<(String, f64)> = report
        .floor
        .iter()
        .filter(|f| f.latency.p50_us > 0.0 && f.latency.p50_us.is_finite())
        .map(|f| {
            let name = format!(
                "pipe floor, {}, {}",
                f.placement.as_str(),
                pacing_label(f.rate_hz)
            );
            (name, f.latency.p50_us)
        })
        .collect();
    let all = series.iter().flat_map(|(_, p)| p.iter());
    let (mut x_lo, mut x_hi, mut y_lo, mut y_hi) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in all {
        x_lo = x_lo.min(x.log2());
        x_hi = x_hi.max(x.log2());
        y_lo = y_lo.min(y.log10());
        y_hi = y_hi.max(y.log10());
    }
    for (_, y) in &floors {
        y_lo = y_lo.min(y.log10());
        y_hi = y_hi.max(y.log10());
    }
    if x_lo > x_hi {
        (x_lo, x_hi) = (6.0, 22.0);
    }
    if y_lo > y_hi {
        (y_lo, y_hi) = (0.0, 3.0);
    }
    if x_hi - x_lo < 1.0 {
        x_lo -= 1.0;
        x_hi += 1.0;
    }
    let (y_lo, y_hi) = (y_lo.floor(), y_hi.ceil().max(y_lo.floor() + 1.0));
    let plot_w = WIDTH - LEFT - RIGHT;
    let plot_h = HEIGHT - TOP - BOTTOM;
    let px = |log2_x: f64| LEFT + (log2_x - x_lo) / (x_hi - x_lo) * plot_w;
    let py = |log10_y: f64| TOP + plot_h - (log10_y - y_lo) / (y_hi - y_lo) * plot_h;

    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{HEIGHT}" viewBox="0 0 {WIDTH} {HEIGHT}" font-family="sans-serif" font-size="12">"#
    );
    let _ = writeln!(
        s,
        r#"<rect width="{WIDTH}" height="{HEIGHT}" fill="white"/>"#
    );
    let _ = writeln!(
        s,
        r#"<text x="{}" y="28" text-anchor="middle" font-size="16">mole bench ipc: one-way latency p50 vs payload size</text>"#,
        WIDTH / 2.0
    );
    // Decade grid and labels on y.
    let mut decade = y_lo;
    while decade <= y_hi + 1e-9 {
        let y = py(decade);
        let _ = writeln!(
            s,
            r##"<line x1="{LEFT}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
            LEFT + plot_w,
            LEFT - 8.0,
            y + 4.0,
            format_us(10f64.powf(decade))
        );
        decade += 1.0;
    }
    // Size ticks on x.
    let mut sizes: Vec<usize> = report.latency.iter().map(|p| p.size).collect();
    sizes.sort_unstable();
    sizes.dedup();
    for size in sizes {
        let x = px((size as f64).log2());
        let _ = writeln!(
            s,
            r##"<line x1="{x:.1}" y1="{TOP}" x2="{x:.1}" y2="{:.1}" stroke="#eee"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
            TOP + plot_h,
            TOP + plot_h + 18.0,
            size_label(size)
        );
    }
    let _ = writeln!(
        s,
        r#"<rect x="{LEFT}" y="{TOP}" width="{plot_w}" height="{plot_h}" fill="none" stroke="black"/>"#
    );
    let _ = writeln!(
        s,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">payload size (log scale)</text>"#,
        LEFT + plot_w / 2.0,
        HEIGHT - 15.0
    );
    let _ = writeln!(
        s,
        r#"<text x="20" y="{:.1}" text-anchor="middle" transform="rotate(-90 20 {:.1})">p50 latency (log scale)</text>"#,
        TOP + plot_h / 2.0,
        TOP + plot_h / 2.0
    );
    for (i, (name, points)) in series.iter().enumerate() {
        let color = COLORS[i % COLORS.len()];
        let coords: Vec<String> = points
            .iter()
            .map(|&(x, y)| format!("{:.1},{:.1}", px(x.log2()), py(y.log10())))
            .collect();
        let _ = writeln!(
            s,
            r#"<polyline fill="none" stroke="{color}" stroke-width="2" points="{}"/>"#,
            coords.join(" ")
        );
        for c in &coords {
            let (cx, cy) = c.split_once(',').unwrap_or(("0", "0"));
            let _ = writeln!(s, r#"<circle cx="{cx}" cy="{cy}" r="3" fill="{color}"/>"#);
        }
        let ly = TOP + 16.0 + 18.0 * i as f64;
        let _ = writeln!(
            s,
            r#"<line x1="{:.1}" y1="{ly:.1}" x2="{:.1}" y2="{ly:.1}" stroke="{color}" stroke-width="2"/><text x="{:.1}" y="{:.1}">{}</text>"#,
            LEFT + 12.0,
            LEFT + 36.0,
            LEFT + 42.0,
            ly + 4.0,
            name
        );
    }
    for (j, (name, p50)) in floors.iter().enumerate() {
        let color = FLOOR_COLORS[j % FLOOR_COLORS.len()];
        let y = py(p50.log10());
        let ly = TOP + 16.0 + 18.0 * (series.len() + j) as f64;
        let _ = writeln!(
            s,
            r#"<line x1="{LEFT}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="{color}" stroke-width="1.5" stroke-dasharray="6 4"/>"#,
            LEFT + plot_w
        );
        let _ = writeln!(
            s,
            r#"<line x1="{:.1}" y1="{ly:.1}" x2="{:.1}" y2="{ly:.1}" stroke="{color}" stroke-width="1.5" stroke-dasharray="6 4"/><text x="{:.1}" y="{:.1}">{name}</text>"#,
            LEFT + 12.0,
            LEFT + 36.0,
            LEFT + 42.0,
            ly + 4.0,
        );
    }
    s.push_str("</svg>\n");
    s
}

fn format_us(us: f64) -> String {
    if us >= 1000.0 {
        format!("{} ms", us / 1000.0)
    } else {
        format!("{us} µs")
    }
}

/// Writes [`render_svg`] to `path`.
pub fn write_plot(report: &IpcReport, path: impl AsRef<Path>) -> Result<(), BenchError> {
    std::fs::write(path, render_svg(report)).map_err(|source| BenchError::Io {
        what: "cannot write the plot",
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{
        ChainPoint, FloorPoint, IpcBenchConfig, LatencyPoint, Placement, Transport, WakeMode,
    };

    fn summary(p50: f64) -> Summary {
        Summary {
            count: 10,
            p50_us: p50,
            p99_us: p50 * 2.0,
            p999_us: p50 * 3.0,
            max_us: p50 * 4.0,
            mean_us: p50,
        }
    }

    fn report() -> IpcReport {
        let mut latency = Vec::new();
        for (transport, wake, base) in [
            (Transport::Runtime, WakeMode::Busy, 1.0),
            (Transport::Raw, WakeMode::Busy, 0.5),
            (Transport::Unix, WakeMode::Blocking, 10.0),
        ] {
            for size in [64, 1 << 20] {
                let p50 = if transport == Transport::Unix && size > 64 {
                    500.0
                } else {
                    base
                };
                latency.push(LatencyPoint {
                    transport,
                    wake,
                    size,
                    latency: summary(p50),
                    handoff: summary(p50 * 1.1),
                    fill: summary(0.1),
                });
            }
        }
        let chain = vec![ChainPoint {
            transport: Transport::Raw,
            hops: 5,
            rate_hz: Some(100.0),
            latency: summary(500.0),
        }];
        let floor = [
            (Placement::Same, None, 5.0),
            (Placement::Same, Some(100.0), 20.0),
            (Placement::Other, None, 50.0),
            (Placement::Other, Some(100.0), 100.0),
        ]
        .into_iter()
        .map(|(placement, rate_hz, p50)| FloorPoint {
            transport: Transport::Pipe,
            placement,
            rate_hz,
            cpus: (placement == Placement::Same).then_some([0, 0]),
            unpinned: (placement == Placement::Other)
                .then(|| "CPU 0 is the only one allowed".to_string()),
            latency: summary(p50),
        })
        .collect();
        let mut r = IpcReport {
            config: IpcBenchConfig::quick(),
            cpus: 2,
            latency,
            throughput: Vec::new(),
            fanout: Vec::new(),
            chain,
            floor,
            ratios: Vec::new(),
            zenoh: None,
        };
        r.ratios = crate::driver::ratios(&r);
        r
    }

    #[test]
    fn sizes_read_as_people_write_them() {
        assert_eq!(size_label(64), "64 B");
        assert_eq!(size_label(16384), "16 KiB");
        assert_eq!(size_label(4 << 20), "4 MiB");
        assert_eq!(size_label(1500), "1500 B");
    }

    #[test]
    fn ratios_divide_the_right_p50s() {
        let r = report();
        let get = |what: &str| r.ratios.iter().find(|x| x.what == what).map(|x| x.value);
        assert_eq!(get("runtime / raw p50 per hop, busy, 64 B"), Some(2.0));
        assert_eq!(get("unix socket / runtime busy p50, 1 MiB"), Some(500.0));
        assert_eq!(get("hand-off p50 1 MiB / 64 B, runtime busy"), Some(1.0));
        assert_eq!(get("runtime / raw p50 per hop, event, 64 B"), None);
    }

    #[test]
    fn ratios_to_the_floor_divide_a_hop_by_the_pipe_wake_up() {
        let mut r = report();
        r.latency.push(LatencyPoint {
            transport: Transport::Raw,
            wake: WakeMode::Event,
            size: 64,
            latency: summary(40.0),
            handoff: summary(41.0),
            fill: summary(0.1),
        });
        r.ratios = crate::driver::ratios(&r);
        let get = |what: &str| r.ratios.iter().find(|x| x.what == what).map(|x| x.value);
        let hop = "raw iceoryx2 event hop / pipe floor p50, flat out";
        assert_eq!(get(&format!("{hop}, same CPU")), Some(8.0));
        assert_eq!(get(&format!("{hop}, other CPU")), Some(0.8));
        let chain = "raw iceoryx2 chain hop / pipe floor p50, paced";
        assert_eq!(
            get(&format!("{chain}, same CPU")),
            Some(5.0),
            "500 µs / 5 hops / 20"
        );
        assert_eq!(get(&format!("{chain}, other CPU")), Some(1.0));
        assert_eq!(
            get("runtime event hop / pipe floor p50, flat out, same CPU"),
            None,
            "no runtime event point, no ratio"
        );
    }

    #[test]
    fn floor_rows_say_where_they_ran_and_why_unpinned() {
        let table = format_table(&report());
        let rows: Vec<&str> = table.lines().filter(|l| l.starts_with("pipe")).collect();
        assert_eq!(rows.len(), 4, "{table}");
        assert!(rows[0].contains("same CPU") && rows[0].contains("flat out"));
        assert!(rows[0].contains("0 → 0") && rows[0].contains("5.00"));
        assert!(rows[1].contains("100 Hz") && rows[1].contains("20.00"));
        assert!(rows[3].contains("other CPU") && rows[3].contains("unpinned"));
        assert!(rows[3].contains("(CPU 0 is the only one allowed)"));
        assert!(table.contains("wake-up floor"));
    }

    #[test]
    fn the_plot_has_one_line_per_series_and_a_legend() {
        let svg = render_svg(&report());
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert_eq!(svg.matches("<polyline").count(), 3);
        assert_eq!(svg.matches("<circle").count(), 6);
        for name in [
            "runtime (busy)",
            "raw iceoryx2 (busy)",
            "unix socket (blocking)",
        ] {
            assert!(svg.contains(name), "legend names {name}");
        }
        assert_eq!(
            svg.matches("stroke-dasharray").count(),
            2 * 4,
            "each floor: a dashed line and its legend"
        );
        assert!(svg.contains("pipe floor, other CPU, 100 Hz"));
        assert!(!svg.contains("NaN") && !svg.contains("inf"));
        // An empty report still renders axes.
        let mut empty = report();
        empty.latency.clear();
        assert!(render_svg(&empty).contains("</svg>"));
        empty.floor.clear();
        assert!(render_svg(&empty).contains("</svg>"));
    }

    /// zenoh's rows sit beside the TCP socket's p50 at the same size, with the throughput in
    /// MB/s and the note on how it ran; without a zenoh run there is no zenoh section.
    #[test]
    fn zenoh_rows_compare_with_the_tcp_socket() {
        let mut r = report();
        assert!(!format_table(&r).contains("zenoh"));
        r.latency.push(LatencyPoint {
            transport: Transport::Tcp,
            wake: WakeMode::Blocking,
            size: 64,
            latency: summary(20.0),
            handoff: summary(20.0),
            fill: summary(0.1),
        });
        r.zenoh = Some(crate::ZenohReport {
            setup: "two processes, peer mode".to_string(),
            latency: [64, 1 << 20]
                .into_iter()
                .map(|size| crate::ZenohLatencyPoint {
                    size,
                    latency: summary(50.0),
                })
                .collect(),
            throughput: crate::ZenohThroughput {
                size: 1 << 20,
                sent: 100,
                received: 100,
                sent_per_s: 1000.0,
                received_per_s: 1000.0,
                megabytes_per_s: 1048.6,
            },
        });
        let table = format_table(&r);
        let rows: Vec<&str> = table
            .lines()
            .filter(|l| l.starts_with("zenoh tcp"))
            .collect();
        assert_eq!(rows.len(), 3, "{table}");
        assert!(rows[0].contains("64 B") && rows[0].trim_end().ends_with("2.50"));
        assert!(rows[1].contains("1 MiB") && rows[1].trim_end().ends_with('-'));
        assert!(rows[2].contains("1048.6") && rows[2].contains("1.0 k"));
        assert!(table.contains("note: two processes, peer mode"));
    }

    #[test]
    fn the_table_names_every_section() {
        let table = format_table(&report());
        for section in [
            "throughput",
            "fan-out",
            "five-hop",
            "ratios",
            "hand-off p50",
        ] {
            assert!(table.contains(section), "{section}");
        }
    }
}
