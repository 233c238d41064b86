//! The flags of a server that shows the stack, the view's and the Foxglove server's alike: where
//! it serves, whether clients may steer, a recording instead of a stack, and where the launcher
//! waits for its URL.

use clap::Args;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::PathBuf;

#[derive(Debug, Clone, Args)]
pub struct ServerFlags {
    /// The port to serve on (default: the server's own; 0: any free port).
    #[arg(long)]
    pub port: Option<u16>,
    /// The address to serve on. Anyone who can reach it sees the run and, unless
    /// --no-controls, can steer the robot.
    #[arg(long, default_value_t = IpAddr::V4(Ipv4Addr::LOCALHOST))]
    pub bind: IpAddr,
    /// Take nothing from clients that steers the run (they only watch).
    #[arg(long)]
    pub no_controls: bool,
    /// Serve this recording (`mole up --record FILE`) instead of a running stack; no IPC.
    #[arg(long, conflicts_with = "no_controls")]
    pub file: Option<PathBuf>,
    /// Once serving, write the URL into this file (the launcher waits for it).
    #[arg(long)]
    pub ready_file: Option<PathBuf>,
}

impl ServerFlags {
    /// Where to serve: `--bind`, and `--port` or else `default_port`.
    pub fn address(&self, default_port: u16) -> SocketAddr {
        SocketAddr::new(self.bind, self.port.unwrap_or(default_port))
    }
}
