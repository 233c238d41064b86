//! Round trips between two threads through the runtime: a quick hop-latency probe.
use mole_runtime::{ClockMode, CommonArgs, Context, Wake};
use mole_types::topics;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

fn main() {
    let mode: ClockMode = std::env::args()
        .nth(1)
        .unwrap_or("realtime".into())
        .parse()
        .unwrap();
    let args = CommonArgs::attach(&format!("pp-{}", std::process::id()), mode);
    let a2 = args.clone();
    let echo = std::thread::spawn(move || {
        let mut ctx =
            Context::with_shutdown_flag("echo", &a2, Arc::new(AtomicBool::new(false))).unwrap();
        let mut sub = ctx.subscriber(topics::PLANNING_CMD).unwrap();
        let mut publ = ctx.publisher(topics::STACK_TICK).unwrap();
        let ws = ctx.waitset().unwrap();
        let w = sub.waker();
        let _g = ws.attach(&w).unwrap();
        ctx.ready();
        let mut n = 0;
        while n < 2000 {
            if ws
                .wait(&mut ctx, Some(Instant::now() + Duration::from_secs(5)))
                .unwrap()
                != Wake::Data
            {
                continue;
            }
            let mut got = vec![];
            sub.drain(|c| got.push(c.header.tick));
            for t in got {
                publ.publish(t, 0, |m| {
                    m.dt = 0.0;
                    m.flags = 0;
                    m.mode = 0;
                })
                .unwrap();
                n += 1;
            }
        }
    });
    let mut ctx =
        Context::with_shutdown_flag("ping", &args, Arc::new(AtomicBool::new(false))).unwrap();
    let mut publ = ctx.publisher(topics::PLANNING_CMD).unwrap();
    let mut sub = ctx.subscriber(topics::STACK_TICK).unwrap();
    let ws = ctx.waitset().unwrap();
    let w = sub.waker();
    let _g = ws.attach(&w).unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let mut samples = vec![];
    for k in 0..2000u64 {
        let t0 = Instant::now();
        publ.publish(k, 0, |c| {
            c.v = 0.0;
            c.omega = 0.0;
            c.mode = 0;
            c._pad = 0;
        })
        .unwrap();
        loop {
            ws.wait(&mut ctx, Some(Instant::now() + Duration::from_secs(5)))
                .unwrap();
            if sub.update() && sub.tick() == Some(k) {
                break;
            }
        }
        samples.push(t0.elapsed().as_secs_f64() * 1e6);
    }
    samples.sort_by(|a, b| a.partial_cmp(b).unwrap());
    println!(
        "{mode}: round trip p50 {:.1} us p99 {:.1} us max {:.1}",
        samples[1000], samples[1980], samples[1999]
    );
    echo.join().unwrap();
}
