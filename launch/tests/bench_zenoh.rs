//! `mole bench ipc`'s zenoh rows, from mole-bridge's `mole-zenoh-bench` next to `mole`.

use std::path::Path;
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_mole");

/// A short `mole bench ipc --json` has zenoh's latency at each size asked for and a throughput
/// point whose every message arrived.
#[test]
fn bench_ipc_json_has_zenoh_rows() {
    let beside = Path::new(BIN).parent().expect("mole's directory");
    assert!(
        beside.join("mole-zenoh-bench").is_file(),
        "no mole-zenoh-bench next to {BIN}: build it first (cargo build -p mole-bridge)"
    );
    let json = std::env::temp_dir().join(format!("mole-bench-zenoh-{}.json", std::process::id()));
    let output = Command::new(BIN)
        .args(["bench", "ipc", "--quick", "--sizes", "64,16384"])
        .arg(format!("--namespace=zbench{}", std::process::id()))
        .arg("--json")
        .arg(&json)
        .output()
        .expect("run mole bench ipc");
    let text = std::fs::read_to_string(&json);
    let _ = std::fs::remove_file(&json);
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "mole bench ipc failed: {}\n{stdout}",
        String::from_utf8_lossy(&output.stderr)
    );
    let report: serde_json::Value =
        serde_json::from_str(&text.expect("the JSON report")).expect("the report is JSON");
    let zenoh = &report["zenoh"];
    let sizes: Vec<u64> = zenoh["latency"]
        .as_array()
        .unwrap_or_else(|| panic!("no zenoh latency rows: {zenoh}"))
        .iter()
        .map(|p| {
            assert_eq!(p["latency"]["count"], 50, "{p}");
            assert!(
                p["latency"]["p50_us"].as_f64().is_some_and(|v| v > 0.0),
                "{p}"
            );
            p["size"].as_u64().expect("a size")
        })
        .collect();
    assert_eq!(sizes, [64, 16384]);
    let throughput = &zenoh["throughput"];
    assert_eq!(throughput["size"], 16384);
    assert!(
        throughput["received"].as_u64().is_some_and(|n| n > 0),
        "{throughput}"
    );
    assert_eq!(throughput["received"], throughput["sent"]);
    assert!(
        stdout.contains("zenoh tcp"),
        "the table has the rows:\n{stdout}"
    );
}
