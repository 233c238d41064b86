//! `mole export FILE OUT --foxglove | --ros2`: a recording rewritten for the tools robotics
//! engineers already use: with Foxglove's well-known schemas, so Foxglove or Lichtblick opens it
//! without a plug-in (`mole_recorder::foxglove`), or as a ROS 2 bag in rosbag2's MCAP profile
//! (`mole_recorder::ros2`).

use crate::Failure;
use clap::Args;
use mole_recorder::Format;
use std::io::Write as _;
use std::path::PathBuf;

#[derive(Debug, Clone, Args)]
#[command(group(clap::ArgGroup::new("target").required(true).args(["foxglove", "ros2"])))]
pub struct ExportArgs {
    /// A recording (`mole up --record FILE`, `mole record`).
    pub file: PathBuf,
    /// The MCAP file to write (replaced if it exists).
    pub out: PathBuf,
    /// Write Foxglove's well-known schemas (`foxglove.PoseInFrame`, `foxglove.LaserScan`,
    /// `foxglove.Grid`, `foxglove.SceneUpdate`) as JSON.
    #[arg(long)]
    pub foxglove: bool,
    /// Write a ROS 2 bag: rosbag2's MCAP profile, CDR messages (`nav_msgs/Odometry`,
    /// `sensor_msgs/LaserScan`, `nav_msgs/OccupancyGrid`, `tf2_msgs/TFMessage`…) stamped with
    /// the simulated time.
    #[arg(long)]
    pub ros2: bool,
}

/// `mole export`: streams the recording into OUT and says what it wrote.
pub fn export(args: &ExportArgs) -> Result<(), Failure> {
    let mut format: Box<dyn Format> = match args.ros2 {
        true => Box::new(mole_recorder::ros2::Ros2::default()),
        false => Box::new(mole_recorder::foxglove::Converter::default()),
    };
    let exported = mole_recorder::export(&args.file, &args.out, format.as_mut())
        .map_err(|e| Failure::input(e.to_string()))?;
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
