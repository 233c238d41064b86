//! When the view makes a frame: one every [`FRAME_PERIOD`], on a fixed schedule from the first,
//! so that a wake-up a little late does not push every later frame back. A wake-up later than a
//! whole period makes one frame, not a burst that catches up: the page is shown the newest.

use std::time::{Duration, Instant};

/// Frames made a second.
pub const FRAMES_PER_SECOND: u32 = 20;
/// The time between two frames.
pub const FRAME_PERIOD: Duration = Duration::from_millis(1000 / FRAMES_PER_SECOND as u64);

/// The view's frame schedule.
#[derive(Debug, Clone)]
pub struct FrameClock {
    next: Instant,
}

impl FrameClock {
    /// A schedule whose first frame is due at `start`.
    pub fn new(start: Instant) -> FrameClock {
        FrameClock { next: start }
    }

    /// When the next frame is due.
    pub fn next(&self) -> Instant {
        self.next
    }

    /// Whether a frame is due at `now`; if so, the one after is scheduled a period on, past
    /// `now` (periods missed altogether are skipped).
    pub fn due(&mut self, now: Instant) -> bool {
        if now < self.next {
            return false;
        }
        self.next += FRAME_PERIOD;
        if self.next <= now {
            let behind = (now - self.next).as_nanos() / FRAME_PERIOD.as_nanos();
            self.next += FRAME_PERIOD * (behind as u32 + 1);
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frames made when the view wakes every `wake` for `span`, from a schedule started at the
    /// first wake-up.
    fn frames(wake: Duration, span: Duration) -> u32 {
        let start = Instant::now();
        let mut clock = FrameClock::new(start);
        let mut made = 0;
        let mut now = start;
        while now < start + span {
            made += u32::from(clock.due(now));
            now += wake;
        }
        made
    }

    /// Woken often (every millisecond, or every 7 ms, off the period), the view makes 20 frames
    /// in each simulated second, 200 in ten.
    #[test]
    fn woken_often_it_makes_twenty_frames_a_second() {
        assert_eq!(
            frames(Duration::from_millis(1), Duration::from_secs(1)),
            FRAMES_PER_SECOND
        );
        assert_eq!(
            frames(Duration::from_millis(7), Duration::from_secs(10)),
            200
        );
        assert_eq!(FRAME_PERIOD * FRAMES_PER_SECOND, Duration::from_secs(1));
    }

    /// A frame due but woken 30 ms late keeps the schedule: the next is due 50 ms after the
    /// first was due, not after the late wake-up; a wake-up three periods late makes one frame
    /// and the schedule goes on from there.
    #[test]
    fn a_late_wake_up_neither_shifts_the_schedule_nor_bursts() {
        let start = Instant::now();
        let mut clock = FrameClock::new(start);
        assert!(clock.due(start));
        assert!(!clock.due(start + Duration::from_millis(49)));
        assert!(clock.due(start + Duration::from_millis(80)));
        assert_eq!(clock.next(), start + Duration::from_millis(100));
        let late = start + Duration::from_millis(260);
        assert!(clock.due(late));
        assert!(!clock.due(late), "a burst to catch up");
        assert_eq!(clock.next(), start + Duration::from_millis(300));
    }
}
