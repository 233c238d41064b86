//! Prints every process's per-topic statistics for a few seconds (a debugging aid).
use mole_runtime::{CommonArgs, Context};
use mole_types::{read_name, topics};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

fn main() {
    let ns = std::env::args().nth(1).unwrap_or("robot0".into());
    let mode = std::env::args()
        .nth(2)
        .unwrap_or("realtime".into())
        .parse()
        .unwrap();
    let args = CommonArgs::attach(&ns, mode);
    let ctx =
        Context::with_shutdown_flag("statsdump", &args, Arc::new(AtomicBool::new(false))).unwrap();
    let mut sub = ctx.subscriber(topics::STACK_STATS).unwrap();
    let end = Instant::now() + Duration::from_secs(4);
    while Instant::now() < end {
        sub.drain(|s| {
            for t in s.topics() {
                println!(
                    "{:>13} {:>24} dir {} rate {:>7.1} p50 {:>8.1} p99 {:>8.1} max {:>8.1}",
                    read_name(&s.process),
                    read_name(&t.topic),
                    t.direction,
                    t.rate_hz,
                    t.latency_p50_us,
                    t.latency_p99_us,
                    t.latency_max_us
                );
            }
        });
        std::thread::sleep(Duration::from_millis(20));
    }
}
