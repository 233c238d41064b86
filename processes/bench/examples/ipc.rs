//! A full `mole bench ipc` run:
//! `cargo run --release -p mole-bench --example ipc [plot.svg [size...]]`
//! (build the probe first: `cargo build --release -p mole-bench --bins`).
//! Prints the table, writes the plot and the JSON report next to it.

fn main() -> std::process::ExitCode {
    let plot = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "bench-ipc.svg".to_string());
    let mut config = mole_bench::IpcBenchConfig::default();
    let sizes: Result<Vec<usize>, _> = std::env::args().skip(2).map(|a| a.parse()).collect();
    match sizes {
        Ok(sizes) if !sizes.is_empty() => config.sizes = sizes,
        Ok(_) => {}
        Err(e) => {
            eprintln!("mole bench ipc: a size is not a number: {e}");
            return std::process::ExitCode::from(2);
        }
    }
    match mole_bench::run_ipc_bench(&config) {
        Ok(report) => {
            mole_bench::print_table(&report);
            if let Err(e) = mole_bench::write_plot(&report, &plot) {
                eprintln!("{e}");
                return std::process::ExitCode::FAILURE;
            }
            if let Ok(json) = serde_json::to_string_pretty(&report) {
                let _ = std::fs::write(format!("{plot}.json"), json);
            }
            std::process::ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("mole bench ipc: {e}");
            std::process::ExitCode::from(2)
        }
    }
}
