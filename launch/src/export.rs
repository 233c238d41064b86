//! `mole export FILE OUT --foxglove`: a recording rewritten with Foxglove's well-known schemas,
//! so Foxglove or Lichtblick opens it without a plug-in (the conversion is
//! `mole_recorder::foxglove`).

use crate::Failure;
use clap::Args;
use std::io::Write as _;
use std::path::PathBuf;

#[derive(Debug, Clone, Args)]
pub struct ExportArgs {
    /// A recording (`mole up --record FILE`, `mole record`).
    pub file: PathBuf,
    /// The MCAP file to write (replaced if it exists).
    pub out: PathBuf,
    /// Write Foxglove's well-known schemas (`foxglove.PoseInFrame`, `foxglove.LaserScan`,
    /// `foxglove.Grid`, `foxglove.SceneUpdate`) as JSON: the only export there is.
    #[arg(long, required = true)]
    pub foxglove: bool,
}

/// `mole export FILE OUT --foxglove`: streams the recording into OUT and says what it wrote.
pub fn export(args: &ExportArgs) -> Result<(), Failure> {
    let exported =
        mole_recorder::export(&args.file, &args.out).map_err(|e| Failure::input(e.to_string()))?;
    let channels: Vec<String> = exported
        .written
        .iter()
        .map(|(topic, count)| format!("{topic} {count}"))
        .collect();
    let written: u64 = exported.written.values().sum();
    // A reader that went away (`mole export … | head`) is no failure.
    let _ = writeln!(
        std::io::stdout().lock(),
        "{}: {written} messages from {} recorded ({})",
        args.out.display(),
        exported.read,
        channels.join(", ")
    );
    Ok(())
}
