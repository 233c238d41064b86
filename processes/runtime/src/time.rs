//! The stack's clock and logging set-up.

use iceoryx2::prelude::*;

/// CLOCK_MONOTONIC in nanoseconds: the clock of every `stamp_ns` and `origin_ns`.
pub fn now_ns() -> u64 {
    match nix::time::clock_gettime(nix::time::ClockId::CLOCK_MONOTONIC) {
        Ok(ts) => (ts.tv_sec() as u64).saturating_mul(1_000_000_000) + ts.tv_nsec() as u64,
        Err(_) => 0,
    }
}

/// How long `work` took, in nanoseconds of [`now_ns`]'s clock.
pub fn timed_ns(work: impl FnOnce()) -> u64 {
    let started = now_ns();
    work();
    now_ns().saturating_sub(started)
}

/// Logs to stderr through `tracing`, filtered by RUST_LOG (default `info`); iceoryx2's own log
/// shows errors only unless IOX2_LOG_LEVEL says otherwise.
pub fn init_tracing(role: &str) {
    set_iceoryx_log_level();
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .try_init();
    tracing::debug!(role, "tracing initialised");
}

/// iceoryx2's own log shows errors only, unless IOX2_LOG_LEVEL says otherwise.
pub(crate) fn set_iceoryx_log_level() {
    set_log_level_from_env_or(LogLevel::Error);
}
