//! A livelock detector: a run makes progress while it explores new area or approaches the
//! planner's current target; a robot that does neither for [`LIVELOCK_S`] (circling before a
//! gap, switching between two frontiers it never reaches) is in a livelock, which the summary
//! counts, with the longest stretch without progress.

/// A stretch without progress this long (s) is a livelock.
pub const LIVELOCK_S: f64 = 30.0;
/// Coming this much closer (m) to the target than ever before is progress.
pub const APPROACH_M: f64 = 0.25;
/// A target that moved this far (m) is a new target: its distance is measured afresh, but the
/// switch itself is not progress (a planner that switches for ever makes none).
pub const NEW_TARGET_M: f64 = 0.5;

/// Progress over a run, fed every truth, every target the planner reports and the explored
/// area at the coverage checks.
#[derive(Debug, Clone)]
pub struct Progress {
    window_ticks: u64,
    last_progress: u64,
    last_tick: u64,
    /// The target and the closest the robot came to it since it became the target.
    target: Option<((f64, f64), f64)>,
    /// The most explored cells seen.
    explored: u64,
    longest: u64,
    livelocks: u32,
    in_livelock: bool,
}

impl Progress {
    /// A detector for steps of `dt` seconds.
    pub fn new(dt: f64) -> Progress {
        let window = if dt > 0.0 { LIVELOCK_S / dt } else { 0.0 };
        Progress {
            window_ticks: (window.ceil() as u64).max(1),
            last_progress: 0,
            last_tick: 0,
            target: None,
            explored: 0,
            longest: 0,
            livelocks: 0,
            in_livelock: false,
        }
    }

    /// The planner's target now (`None`: it has none).
    pub fn on_target(&mut self, target: Option<(f64, f64)>) {
        self.target = match (target, self.target) {
            (None, _) => None,
            (Some(t), Some((old, best))) if (t.0 - old.0).hypot(t.1 - old.1) < NEW_TARGET_M => {
                Some((t, best))
            }
            (Some(t), _) => Some((t, f64::INFINITY)),
        };
    }

    /// The robot's true position at `tick`.
    pub fn on_position(&mut self, tick: u64, x: f64, y: f64) {
        if let Some(((tx, ty), best)) = self.target.as_mut() {
            let d = (x - *tx).hypot(y - *ty);
            if !best.is_finite() {
                *best = d;
            } else if d < *best - APPROACH_M {
                *best = d;
                self.progress(tick);
            }
        }
        self.advance(tick);
    }

    /// Cells explored at `tick` (the frontier grid's explored reachable cells).
    pub fn on_explored(&mut self, tick: u64, cells: u64) {
        if cells > self.explored {
            self.explored = cells;
            self.progress(tick);
        }
        self.advance(tick);
    }

    fn progress(&mut self, tick: u64) {
        self.last_progress = self.last_progress.max(tick);
        self.in_livelock = false;
    }

    fn advance(&mut self, tick: u64) {
        self.last_tick = self.last_tick.max(tick);
        let stretch = self.last_tick.saturating_sub(self.last_progress);
        self.longest = self.longest.max(stretch);
        if stretch >= self.window_ticks && !self.in_livelock {
            self.in_livelock = true;
            self.livelocks += 1;
        }
    }

    /// The longest stretch without progress, in steps.
    pub fn longest_ticks(&self) -> u64 {
        self.longest
    }

    /// Stretches without progress of at least [`LIVELOCK_S`].
    pub fn livelocks(&self) -> u32 {
        self.livelocks
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Circling in front of a target it never reaches is a livelock, counted once however long
    /// it lasts; approaching the target or new area ends it.
    #[test]
    fn circling_before_a_target_is_a_livelock_and_progress_ends_it() {
        let mut p = Progress::new(0.1); // 300 steps make 30 s
        p.on_target(Some((5.0, 0.0)));
        for tick in 0..1000 {
            let a = tick as f64 * 0.1;
            p.on_position(tick, 1.0 + 0.3 * a.cos(), 0.3 * a.sin());
        }
        assert_eq!(p.livelocks(), 1);
        assert!(p.longest_ticks() >= 990, "{}", p.longest_ticks());
        // It drives to the target: progress, then new area, and no new livelock.
        for (i, tick) in (1000..1040).enumerate() {
            p.on_position(tick, 1.0 + 0.1 * i as f64, 0.0);
        }
        p.on_explored(1040, 10);
        for tick in 1040..1200 {
            p.on_position(tick, 5.0, 0.0);
        }
        assert_eq!(p.livelocks(), 1);
    }

    /// Switching between two targets without approaching either is no progress.
    #[test]
    fn switching_targets_for_ever_is_no_progress() {
        let mut p = Progress::new(0.1);
        for tick in 0..400 {
            let t = if tick % 20 < 10 {
                (5.0, 0.0)
            } else {
                (-5.0, 0.0)
            };
            p.on_target(Some(t));
            p.on_position(tick, 0.0, 0.0);
        }
        assert_eq!(p.livelocks(), 1);
        assert_eq!(p.longest_ticks(), 399);
    }

    /// New area every few steps keeps a run out of livelock, with no target at all.
    #[test]
    fn new_area_is_progress_without_a_target() {
        let mut p = Progress::new(0.1);
        for tick in 0..2000 {
            p.on_position(tick, 0.0, 0.0);
            if tick % 10 == 0 {
                p.on_explored(tick, tick / 10);
            }
        }
        assert_eq!(p.livelocks(), 0);
        assert!(p.longest_ticks() <= 10);
    }
}
