//! The recorder's loop: when it drains its queues into the writer and when the file's current
//! chunk is closed.
//!
//! Lockstep: the world's truth wakes it once a step and it drains every queue. Realtime: nothing
//! wakes it; it drains every [`REALTIME_DRAIN`]. Either way the current chunk is closed every
//! [`FLUSH_EVERY`]. It ends on a shutdown, or when the writer stopped (its error comes with
//! [`crate::WriterThread::finish`]).

use crate::{Record, Taps};
use mole_runtime::{ClockMode, Context, RuntimeError, WaitSet, Wake};
use std::time::{Duration, Instant};

/// How often a realtime recorder drains its queues. The smallest queue of a topic published
/// every step holds 2 samples (`localization/particles`, `world/map`), 20 ms at 100 Hz: draining
/// every 10 ms leaves a scheduling delay of 10 ms before a sample is lost (and counted).
pub const REALTIME_DRAIN: Duration = Duration::from_millis(10);
/// How often the current chunk is closed and handed to the file: what a killed recorder loses.
pub const FLUSH_EVERY: Duration = Duration::from_secs(1);

/// What the loop did, for the log.
#[derive(Debug, Clone, Copy, Default)]
pub struct Reading {
    /// Wake-ups by a publisher (the truth in lockstep; none in realtime).
    pub woken: u64,
    /// Drains of every queue.
    pub drains: u64,
}

/// Where the records read from the stack go: the recorder's writer thread, or `mole-foxglove`'s
/// channels.
pub trait RecordSink {
    /// Takes every record of `out`; false when the sink has stopped (the loop then ends).
    fn send(&mut self, out: &mut Vec<Record>) -> bool;
    /// Hands on what it holds (every [`FLUSH_EVERY`]); false when the sink has stopped.
    fn flush(&mut self) -> bool;
    /// Whether it wants the samples now (the world's map it always gets).
    fn wants_samples(&self) -> bool {
        true
    }
}

/// Reads the stack's topics into `writer` until a shutdown or the writer's end (see the
/// module docs); `waitset` has the taps' wakers attached.
pub fn read_until_shutdown(
    waitset: &WaitSet,
    ctx: &mut Context,
    taps: &mut Taps,
    writer: &mut dyn RecordSink,
) -> Result<Reading, RuntimeError> {
    let lockstep = ctx.mode() == ClockMode::Lockstep;
    let mut next_drain = Instant::now();
    let mut next_flush = Instant::now() + FLUSH_EVERY;
    let mut writing = true;
    // Wake-ups by a publisher (the truth in lockstep; none in realtime) and drains, for the log.
    let (mut woken, mut drains) = (0u64, 0u64);
    while writing {
        let wake = waitset.wait(ctx, Some(next_drain.min(next_flush)))?;
        woken += u64::from(wake == Wake::Data);
        if lockstep || Instant::now() >= next_drain {
            drains += 1;
            taps.seen.skip_samples = !writer.wants_samples();
            taps.drain();
            writing = writer.send(&mut taps.seen.out);
            next_drain = Instant::now() + REALTIME_DRAIN;
        }
        if writing && Instant::now() >= next_flush {
            writing = writer.flush();
            next_flush = Instant::now() + FLUSH_EVERY;
        }
        if wake == Wake::Shutdown {
            break;
        }
    }
    Ok(Reading { woken, drains })
}
