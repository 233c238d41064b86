//! The recorder's writer thread: the records read from the stack go through a bounded queue to
//! the file (chunks, LZ4), and back to the reader to be finished once it hung up.

use crate::{Record, RecordError, RecordSink, Recording, Taps, Written};
use std::sync::mpsc::{SyncSender, sync_channel};
use std::thread::JoinHandle;

/// Records between the reader and the writer: about 70 steps of the default stack. Full, it
/// holds the reader back, and then (lockstep) the stack, rather than losing samples.
pub const WRITER_QUEUE: usize = 1024;

/// The writer thread and the queue to it.
pub struct WriterThread {
    records: SyncSender<Record>,
    /// The writer thread, which hands the file back to be finished once the reader hung up.
    thread: JoinHandle<Result<Recording, RecordError>>,
}

impl WriterThread {
    /// The writer thread: applies every record to the file until the reader hangs up.
    pub fn start(mut recording: Recording) -> std::io::Result<WriterThread> {
        let (records, received) = sync_channel(WRITER_QUEUE);
        let thread = std::thread::Builder::new()
            .name("writer".into())
            .spawn(move || {
                for record in received {
                    recording.apply(record)?;
                }
                Ok(recording)
            })?;
        Ok(WriterThread { records, thread })
    }

    /// Hands `out` to the writer; false when the writer has stopped (its error comes with
    /// [`WriterThread::finish`]).
    fn hand_over(&self, out: &mut Vec<Record>) -> bool {
        out.drain(..)
            .all(|record| self.records.send(record).is_ok())
    }

    /// Writes what the taps still hold (the queues, the newest sample of every decimated topic),
    /// hangs up and finishes the file with the taps' totals, timed by the world's step (by
    /// `rate_hz` if its map never came).
    pub fn finish(
        self,
        taps: &mut Taps,
        rate_hz: f64,
    ) -> Result<Written, Box<dyn std::error::Error>> {
        taps.drain();
        taps.last_samples();
        self.hand_over(&mut taps.seen.out);
        let totals = taps.totals();
        let fallback_period_ns = (1e9 / rate_hz).round() as u64;
        let period_ns = taps.seen.period_ns.unwrap_or(fallback_period_ns);
        let WriterThread { records, thread } = self;
        drop(records);
        let recording = thread
            .join()
            .map_err(|_| "the recorder's writer thread panicked")??;
        Ok(recording.finish(period_ns, totals)?)
    }
}

impl RecordSink for WriterThread {
    fn send(&mut self, out: &mut Vec<Record>) -> bool {
        self.hand_over(out)
    }

    /// Closes the current chunk and hands it to the file.
    fn flush(&mut self) -> bool {
        self.records.send(Record::Flush).is_ok()
    }
}
