//! The quick configuration end to end: real probe processes on every transport. Checks the
//! report's structure and that every number is positive and finite (no timing assertions), that
//! the pipe wake-up floor's rows reach the JSON, and that no node of the run is left behind.

use mole_bench::{IpcBenchConfig, Placement, Summary, Transport, WakeMode, run_ipc_bench};
use std::path::PathBuf;

fn check(s: &Summary, what: &str) {
    assert!(s.count > 0, "{what}: no samples");
    for v in [s.p50_us, s.p99_us, s.p999_us, s.max_us, s.mean_us] {
        assert!(v.is_finite() && v > 0.0, "{what}: {s:?}");
    }
    assert!(s.p50_us <= s.p99_us && s.p99_us <= s.p999_us && s.p999_us <= s.max_us);
}

#[test]
fn quick_run_reports_every_point() {
    let config = IpcBenchConfig {
        namespace: format!("bq{}", std::process::id()),
        probe: Some(PathBuf::from(env!("CARGO_BIN_EXE_mole-bench-probe"))),
        ..IpcBenchConfig::quick()
    };
    let report = run_ipc_bench(&config).expect("the quick run succeeds");

    // 2 sizes × (runtime, raw × busy, event + unix + tcp).
    assert_eq!(report.latency.len(), 2 * 6);
    for p in &report.latency {
        let what = format!("{:?} {:?} {}", p.transport, p.wake, p.size);
        let n = config.samples_for(p.size);
        assert_eq!(p.latency.count, n, "{what}");
        check(&p.latency, &what);
        check(&p.handoff, &what);
        assert!(p.handoff.p50_us >= p.latency.p50_us, "{what}");
        assert!(p.fill.p50_us.is_finite() && p.fill.p50_us >= 0.0);
        assert_eq!(p.transport.is_ipc(), p.wake != WakeMode::Blocking);
    }
    assert_eq!(report.throughput.len(), 2 * 4);
    for p in &report.throughput {
        assert!(
            p.sent > 0 && p.received > 0 && p.received <= p.sent,
            "{p:?}"
        );
        for v in [p.sent_per_s, p.received_per_s, p.bytes_per_s] {
            assert!(v.is_finite() && v > 0.0, "{p:?}");
        }
        if !p.transport.is_ipc() {
            assert_eq!(p.received, p.sent, "sockets lose nothing");
        }
    }
    assert_eq!(report.fanout.len(), 2 * 2);
    for p in &report.fanout {
        check(&p.latency, "fan-out");
        assert_eq!(p.latency.count, config.fanout_samples);
    }
    assert_eq!(report.chain.len(), 4);
    for p in &report.chain {
        assert_eq!(p.hops, 5);
        check(&p.latency, "chain");
    }
    assert!(
        report
            .chain
            .iter()
            .any(|c| c.transport == Transport::Raw && c.rate_hz == Some(100.0))
    );
    // The floor: same CPU and other CPU, each flat out and paced, pinned or saying why not.
    let floors: Vec<(Placement, Option<f64>)> = report
        .floor
        .iter()
        .map(|f| (f.placement, f.rate_hz))
        .collect();
    assert_eq!(
        floors,
        [
            (Placement::Same, None),
            (Placement::Same, Some(100.0)),
            (Placement::Other, None),
            (Placement::Other, Some(100.0)),
        ]
    );
    for f in &report.floor {
        let what = format!("floor {:?} {:?}", f.placement, f.rate_hz);
        assert_eq!(f.transport, Transport::Pipe);
        let n = match f.rate_hz {
            None => config.floor_samples,
            Some(_) => config.floor_paced_samples,
        };
        assert_eq!(f.latency.count, n, "{what}");
        check(&f.latency, &what);
        match (f.cpus, &f.unpinned) {
            (Some([a, b]), None) => assert_eq!(a == b, f.placement == Placement::Same, "{what}"),
            (None, Some(why)) => assert!(!why.is_empty(), "{what}"),
            other => panic!("{what}: pinned and unpinned at once: {other:?}"),
        }
    }
    assert!(
        report.ratios.iter().any(|r| r.what.contains("pipe floor")),
        "{:?}",
        report.ratios
    );
    assert!(!report.ratios.is_empty());
    for r in &report.ratios {
        assert!(r.value.is_finite() && r.value > 0.0, "{r:?}");
    }

    let json = serde_json::to_value(&report).expect("serialises");
    assert!(json["latency"][0]["latency"]["p50_us"].is_number());
    assert_eq!(json["latency"][0]["transport"], "runtime");
    let floor = json["floor"]
        .as_array()
        .expect("the floor rows are in the JSON");
    assert_eq!(floor.len(), 4);
    for row in floor {
        assert_eq!(row["transport"], "pipe");
        assert!(row["placement"] == "same" || row["placement"] == "other");
        assert!(row["latency"]["p50_us"].is_number() && row["latency"]["p99_us"].is_number());
    }
    assert_eq!(floor[1]["rate_hz"], 100.0);
    assert!(floor[0]["rate_hz"].is_null());
    let svg = mole_bench::render_svg(&report);
    assert_eq!(svg.matches("<polyline").count(), 6);
    assert_eq!(
        svg.matches("stroke-dasharray").count(),
        2 * 4,
        "the floor's lines"
    );
    let table = mole_bench::format_table(&report);
    assert!(table.contains("five-hop") && table.contains("wake-up floor"));

    let left = mole_bench::live_bench_nodes(&config.namespace);
    assert!(left.is_empty(), "nodes left behind: {left:?}");
}

#[test]
fn an_unsupported_size_is_refused_before_anything_starts() {
    let config = IpcBenchConfig {
        sizes: vec![64, 3000],
        probe: Some(PathBuf::from("/nonexistent")),
        ..IpcBenchConfig::quick()
    };
    assert!(matches!(
        run_ipc_bench(&config),
        Err(mole_bench::BenchError::UnsupportedSize(3000))
    ));
}
