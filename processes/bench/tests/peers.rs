//! `mole bench peers`' quick run end to end: the loop on raw iceoryx2, mole's runtime and dora-rs
//! (scripts/dora-env.sh installs dora; without it the dora rows are skipped with the reason, and
//! under CI this test fails instead). Counts, no timing assertions: every build brings back
//! every loop it was asked for, in order; a paced loop keeps its pace; every number is positive;
//! and nothing of the run is left behind (no node, no file, no shared memory of dora's).

use mole_bench::live_bench_nodes;
use mole_bench::peers::{Peer, PeerBenchConfig, run_peer_bench};
use std::path::PathBuf;

#[test]
fn every_build_brings_back_every_loop() {
    let ci = std::env::var_os("CI").is_some_and(|v| !v.is_empty());
    let dora_dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../target/dora-env");
    let config = PeerBenchConfig {
        namespace: format!("bp{}", std::process::id()),
        probe: Some(PathBuf::from(env!("CARGO_BIN_EXE_mole-bench-probe"))),
        dora_dir,
        require_dora: ci,
        ..PeerBenchConfig::quick()
    };
    let zenoh_before = zenoh_segments();
    let report = run_peer_bench(&config).expect("the quick run succeeds");
    let mut peers = vec![Peer::RawIceoryx2, Peer::Mole];
    match report.skipped.as_slice() {
        [] => peers.push(Peer::Dora),
        [skipped] => {
            assert_eq!(skipped.peer, Peer::Dora);
            eprintln!("SKIPPED the dora-rs rows: {}", skipped.reason);
        }
        more => panic!("only dora may be skipped: {more:?}"),
    }
    assert_eq!(
        report.points.len(),
        peers.len() * 2 * 2,
        "{:?}",
        report.points
    );
    for &peer in &peers {
        for &size in &config.sizes {
            for paced in [false, true] {
                let p = report
                    .point(peer, size, paced)
                    .unwrap_or_else(|| panic!("{peer:?} {size} B paced={paced} missing"));
                let what = format!("{} {size} B paced={paced}: {p:?}", peer.as_str());
                let loops = if paced {
                    config.paced_loops
                } else {
                    config.loops
                };
                assert_eq!(p.latency.count, loops, "{what}");
                let s = &p.latency;
                assert!(
                    s.p50_us > 0.0 && s.p50_us <= s.p99_us && s.p99_us <= s.max_us,
                    "{what}"
                );
                assert!(
                    p.cpu_us_per_loop > 0.0 && p.cpu_us_per_loop.is_finite(),
                    "{what}"
                );
                assert!(p.loops_per_s > 0.0, "{what}");
                if paced {
                    // A paced source sends one loop per period: never faster than its rate.
                    assert!(p.loops_per_s <= config.rate_hz * 1.1, "{what}");
                }
            }
        }
    }
    // mole's ratios against every measured peer, per size and pacing, p50 and CPU.
    assert_eq!(report.ratios.len(), (peers.len() - 1) * 2 * 2 * 2);
    assert!(live_bench_nodes(&config.namespace).is_empty());
    let leftovers: Vec<_> = std::fs::read_dir(std::env::temp_dir())
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().contains(&config.namespace))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    let zenoh_after = zenoh_segments();
    let left: Vec<_> = zenoh_after
        .iter()
        .filter(|s| !zenoh_before.contains(s))
        .collect();
    assert!(
        left.is_empty(),
        "dora's shared memory left in /dev/shm: {left:?}"
    );
}

/// zenoh's shared-memory segments, which dora's data plane creates.
fn zenoh_segments() -> Vec<PathBuf> {
    std::fs::read_dir("/dev/shm")
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "zenoh"))
        .collect()
}
