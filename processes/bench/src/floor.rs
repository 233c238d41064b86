//! The wake-up floor: a plain pipe between two processes, on one CPU or on two, flat out or
//! paced. What the kernel needs to wake a sleeping process, with nothing of iceoryx2 or the
//! runtime on top: every event-woken transport above pays at least this per hop.

use nix::sched::{CpuSet, sched_getaffinity, sched_setaffinity};
use nix::unistd::Pid;
use serde::Serialize;
use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::AsFd;
use std::time::{Duration, Instant};

/// Where the waker (the driver) and the sleeper (the probe) run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Placement {
    /// Both on one CPU: the woken probe runs once the driver gives the CPU up.
    Same,
    /// On two CPUs: the wake-up crosses CPUs (an inter-processor interrupt when the probe's
    /// CPU is idle).
    Other,
}

impl Placement {
    /// The name in tables and plots.
    pub fn as_str(self) -> &'static str {
        match self {
            Placement::Same => "same CPU",
            Placement::Other => "other CPU",
        }
    }
}

/// The CPUs (waker, sleeper) for `placement`, from the CPUs this thread may run on; why not
/// when there are too few.
pub(crate) fn choose_cpus(allowed: &[usize], placement: Placement) -> Result<[usize; 2], String> {
    match (placement, allowed) {
        (_, []) => Err("no CPU in this thread's affinity mask".to_string()),
        (Placement::Same, [first, ..]) => Ok([*first, *first]),
        (Placement::Other, [first, second, ..]) => Ok([*first, *second]),
        (Placement::Other, [only]) => Err(format!("CPU {only} is the only one allowed")),
    }
}

/// The first slot boundary `start + k·period` strictly after `now`: sleeping until it wakes
/// on the next slot, however late this one was (a late sample skips slots, never bursts).
pub(crate) fn next_slot(start: Instant, period: Duration, now: Instant) -> Instant {
    let period_ns = period.as_nanos();
    if period_ns == 0 {
        return now;
    }
    let elapsed_ns = now.saturating_duration_since(start).as_nanos();
    let slot_ns = (elapsed_ns / period_ns + 1) * period_ns;
    start + Duration::from_nanos(u64::try_from(slot_ns).unwrap_or(u64::MAX))
}

/// The CPUs the calling thread may run on.
fn allowed_cpus(mask: &CpuSet) -> Vec<usize> {
    (0..CpuSet::count())
        .filter(|&cpu| mask.is_set(cpu).unwrap_or(false))
        .collect()
}

fn only(cpu: usize) -> nix::Result<CpuSet> {
    let mut set = CpuSet::new();
    set.set(cpu)?;
    Ok(set)
}

/// The calling thread's CPU affinity for one floor measurement: pinned to the sleeper's CPU
/// while the probe is spawned (a child inherits its parent's mask), then to the waker's;
/// restored to what it was when dropped.
pub(crate) struct Pinning {
    original: Option<CpuSet>,
    /// (waker, sleeper) when both are pinned.
    pub cpus: Option<[usize; 2]>,
    /// Why both run unpinned.
    pub unpinned: Option<String>,
}

impl Pinning {
    /// Pins the calling thread to the sleeper's CPU of `placement`, after checking that the
    /// waker's CPU is allowed too; on refusal leaves the thread as it was and says why.
    pub fn for_spawn(placement: Placement) -> Pinning {
        let original = match sched_getaffinity(Pid::from_raw(0)) {
            Ok(mask) => mask,
            Err(e) => {
                return Pinning {
                    original: None,
                    cpus: None,
                    unpinned: Some(format!("sched_getaffinity refused: {e}")),
                };
            }
        };
        let mut pinning = Pinning {
            original: Some(original),
            cpus: None,
            unpinned: None,
        };
        let result = choose_cpus(&allowed_cpus(&original), placement).and_then(|cpus| {
            for cpu in cpus {
                only(cpu)
                    .and_then(|set| sched_setaffinity(Pid::from_raw(0), &set))
                    .map_err(|e| format!("sched_setaffinity to CPU {cpu} refused: {e}"))?;
            }
            Ok(cpus)
        });
        match result {
            Ok(cpus) => pinning.cpus = Some(cpus),
            Err(why) => {
                pinning.restore();
                pinning.unpinned = Some(why);
            }
        }
        pinning
    }

    /// Moves the calling thread to the waker's CPU (the probe, spawned meanwhile, stays on the
    /// sleeper's). Both CPUs were checked in [`Pinning::for_spawn`].
    pub fn move_to_waker(&mut self) {
        if let Some([waker, _]) = self.cpus
            && let Err(e) = only(waker).and_then(|set| sched_setaffinity(Pid::from_raw(0), &set))
        {
            self.restore();
            self.cpus = None;
            self.unpinned = Some(format!(
                "sched_setaffinity to CPU {waker} refused: {e} (the probe stayed pinned)"
            ));
        }
    }

    fn restore(&self) {
        if let Some(original) = &self.original {
            let _ = sched_setaffinity(Pid::from_raw(0), original);
        }
    }
}

impl Drop for Pinning {
    fn drop(&mut self) {
        self.restore();
    }
}

/// The two ends of a pipe pair as one stream: reads `rx`, writes `tx`. With a timeout every
/// read first waits in poll(2) for at most that long, so a silent peer is an error and not a
/// hang (the driver's side); without one a read blocks, which is the wake-up being measured
/// (the probe's side; the driver's exit closes the pipe and ends the read).
pub(crate) struct PipePair {
    rx: File,
    tx: File,
    timeout: Option<Duration>,
}

impl PipePair {
    pub fn new(rx: File, tx: File, timeout: Option<Duration>) -> Self {
        PipePair { rx, tx, timeout }
    }
}

impl Read for PipePair {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
        if let Some(timeout) = self.timeout {
            let mut fds = [PollFd::new(self.rx.as_fd(), PollFlags::POLLIN)];
            let ready = poll(
                &mut fds,
                PollTimeout::try_from(timeout).unwrap_or(PollTimeout::MAX),
            )?;
            if ready == 0 {
                return Err(std::io::ErrorKind::TimedOut.into());
            }
        }
        self.rx.read(buf)
    }
}

impl Write for PipePair {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.tx.write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.tx.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpus_are_one_for_same_and_two_for_other() {
        assert_eq!(choose_cpus(&[2, 5], Placement::Same), Ok([2, 2]));
        assert_eq!(choose_cpus(&[2, 5], Placement::Other), Ok([2, 5]));
        let one = choose_cpus(&[3], Placement::Other).expect_err("one CPU cannot be two");
        assert!(one.contains("CPU 3"), "{one}");
        assert_eq!(choose_cpus(&[3], Placement::Same), Ok([3, 3]));
        assert!(choose_cpus(&[], Placement::Same).is_err());
    }

    #[test]
    fn the_next_slot_is_strictly_ahead_and_on_the_grid() {
        let start = Instant::now();
        let period = Duration::from_millis(10);
        let at = |ms: u64| start + Duration::from_millis(ms);
        assert_eq!(next_slot(start, period, at(0)), at(10));
        assert_eq!(next_slot(start, period, at(3)), at(10));
        assert_eq!(
            next_slot(start, period, at(10)),
            at(20),
            "on a boundary: the next one"
        );
        assert_eq!(
            next_slot(start, period, at(47)),
            at(50),
            "late: skips, no burst"
        );
        assert_eq!(next_slot(start, Duration::ZERO, at(5)), at(5));
    }

    #[test]
    fn a_pipe_pair_carries_bytes_and_times_out_on_silence() {
        let (rx, tx_peer) = std::io::pipe().expect("pipe");
        let (_rx_peer, tx) = std::io::pipe().expect("pipe");
        let mut peer_tx = File::from(std::os::fd::OwnedFd::from(tx_peer));
        let mut pair = PipePair::new(
            File::from(std::os::fd::OwnedFd::from(rx)),
            File::from(std::os::fd::OwnedFd::from(tx)),
            Some(Duration::from_millis(20)),
        );
        peer_tx.write_all(b"wake").expect("write");
        let mut got = [0u8; 4];
        pair.read_exact(&mut got).expect("read");
        assert_eq!(&got, b"wake");
        // The peer stays open and silent: the read must give up, not block for ever.
        let (done, silent) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let _ = done.send(pair.read(&mut got).map_err(|e| e.kind()));
        });
        let result = silent
            .recv_timeout(Duration::from_secs(10))
            .expect("a silent peer hung the read");
        assert_eq!(result, Err(std::io::ErrorKind::TimedOut));
        drop(peer_tx);
    }

    #[test]
    fn pinning_is_undone_when_dropped() {
        let before = sched_getaffinity(Pid::from_raw(0)).expect("affinity");
        let pinning = Pinning::for_spawn(Placement::Same);
        if let Some([_, sleeper]) = pinning.cpus {
            let now = sched_getaffinity(Pid::from_raw(0)).expect("affinity");
            assert_eq!(allowed_cpus(&now), vec![sleeper]);
        } else {
            assert!(pinning.unpinned.is_some(), "unpinned without a reason");
        }
        drop(pinning);
        let after = sched_getaffinity(Pid::from_raw(0)).expect("affinity");
        assert_eq!(allowed_cpus(&after), allowed_cpus(&before));
    }
}
