//! A livelock detector: a run makes progress while it explores new area or approaches the
//! planner's current target; a robot that does neither for [`LIVELOCK_S`] (circling before a
//! gap, switching between two frontiers it never reaches) is in a livelock, which the summary
//! counts, with the longest stretch without progress.
//!
//! The approach is measured along the path the planner published to the target, when it has
//! one that ends there (from the robot's nearest point on it to its end), else in a straight
//! line: in a maze the way to a far frontier first leads away from it, and a straight-line
//! detector called a robot driving its path without a stop a livelock.

/// A stretch without progress this long (s) is a livelock.
pub const LIVELOCK_S: f64 = 30.0;
/// Coming this much closer (m) to the target than ever before is progress.
pub const APPROACH_M: f64 = 0.25;
/// A target that moved this far (m) is a new target: its distance is measured afresh, but the
/// switch itself is not progress (a planner that switches for ever makes none).
pub const NEW_TARGET_M: f64 = 0.5;

/// Planner statuses kept by tick, so each check is judged against the target of its own step.
const TARGET_RING: usize = 64;
/// Waypoints kept per status: the most a `planning/status` carries.
const PATH_POINTS: usize = mole_types::MAX_PATH;
/// Checks waiting for the status of their step (it may arrive after the grid of that step).
const PENDING: usize = 16;

/// One coverage check: the step, the explored cells, the robot's true position.
#[derive(Debug, Clone, Copy, Default)]
struct Check {
    tick: u64,
    explored: u64,
    position: (f64, f64),
}

/// Progress over a run, judged at the coverage checks: each check (explored cells and the true
/// position of its step) against the planner's target of that same step, whichever of the grid
/// and the status came first, so the result does not depend on the order messages arrive in.
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
    /// The planner's target of each recent step: `(tick, target)` at `tick % TARGET_RING`.
    targets: [(u64, Option<(f64, f64)>); TARGET_RING],
    /// The path to it of each of those steps: its waypoints in the slot's `PATH_POINTS`, and how
    /// many (sized once).
    paths: Vec<[f32; 2]>,
    path_lens: [usize; TARGET_RING],
    /// The newest step a status arrived for.
    status_tick: Option<u64>,
    pending: [Check; PENDING],
    n_pending: usize,
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
            targets: [(u64::MAX, None); TARGET_RING],
            paths: vec![[0.0; 2]; TARGET_RING * PATH_POINTS],
            path_lens: [0; TARGET_RING],
            status_tick: None,
            pending: [Check::default(); PENDING],
            n_pending: 0,
        }
    }

    /// The planner's target at step `tick` (`None`: it has none) and its path there (empty:
    /// none); judges the checks that waited for it.
    pub fn on_status(&mut self, tick: u64, target: Option<(f64, f64)>, path: &[[f32; 2]]) {
        let slot = (tick % TARGET_RING as u64) as usize;
        self.targets[slot] = (tick, target);
        let n = path.len().min(PATH_POINTS);
        self.paths[slot * PATH_POINTS..][..n].copy_from_slice(&path[..n]);
        self.path_lens[slot] = n;
        self.status_tick = Some(self.status_tick.map_or(tick, |t| t.max(tick)));
        let mut kept = 0;
        for i in 0..self.n_pending {
            let check = self.pending[i];
            if check.tick <= tick {
                self.judge(check);
            } else {
                self.pending[kept] = check;
                kept += 1;
            }
        }
        self.n_pending = kept;
    }

    /// A coverage check at step `tick`: the explored cells and the robot's true position then.
    pub fn on_check(&mut self, tick: u64, explored: u64, position: (f64, f64)) {
        let check = Check {
            tick,
            explored,
            position,
        };
        if self.status_tick.is_some_and(|t| t >= tick) {
            self.judge(check);
        } else if self.n_pending < PENDING {
            self.pending[self.n_pending] = check;
            self.n_pending += 1;
        } else {
            // The planner is far behind (or silent): judge the oldest against what is known.
            let oldest = self.pending[0];
            self.pending.copy_within(1..PENDING, 0);
            self.pending[PENDING - 1] = check;
            self.judge(oldest);
        }
    }

    /// The detector at the end of the run: the checks still waiting judged against the newest
    /// target known.
    pub fn finished(&self) -> Progress {
        let mut done = self.clone();
        for i in 0..done.n_pending {
            let check = done.pending[i];
            done.judge(check);
        }
        done.n_pending = 0;
        done
    }

    /// The target in effect at `tick` and its ring slot: that step's, else the newest earlier
    /// one kept.
    fn target_at(&self, tick: u64) -> Option<((f64, f64), usize)> {
        (0..TARGET_RING as u64)
            .filter_map(|back| tick.checked_sub(back))
            .find_map(|t| {
                let slot = (t % TARGET_RING as u64) as usize;
                let (at, target) = self.targets[slot];
                (at == t).then_some(target.map(|target| (target, slot)))
            })
            .flatten()
    }

    /// How far `position` is from `target`: along the slot's path when it ends at the target,
    /// else in a straight line.
    fn distance(&self, position: (f64, f64), target: (f64, f64), slot: usize) -> f64 {
        let path = &self.paths[slot * PATH_POINTS..][..self.path_lens[slot]];
        let ends_there = path.last().is_some_and(|end| {
            (f64::from(end[0]) - target.0).hypot(f64::from(end[1]) - target.1) < NEW_TARGET_M
        });
        if path.len() < 2 || !ends_there {
            return (position.0 - target.0).hypot(position.1 - target.1);
        }
        length_left_along(path, position)
    }

    fn judge(&mut self, check: Check) {
        let found = self.target_at(check.tick);
        let target = found.map(|(t, _)| t);
        self.target = match (target, self.target) {
            (None, _) => None,
            (Some(t), Some((old, best))) if (t.0 - old.0).hypot(t.1 - old.1) < NEW_TARGET_M => {
                Some((t, best))
            }
            (Some(t), _) => Some((t, f64::INFINITY)),
        };
        let d = found.map(|(t, slot)| self.distance(check.position, t, slot));
        if let (Some((_, best)), Some(d)) = (self.target.as_mut(), d) {
            if !best.is_finite() {
                *best = d;
            } else if d < *best - APPROACH_M {
                *best = d;
                self.progress(check.tick);
            }
        }
        if check.explored > self.explored {
            self.explored = check.explored;
            self.progress(check.tick);
        }
        self.last_tick = self.last_tick.max(check.tick);
        let stretch = self.last_tick.saturating_sub(self.last_progress);
        self.longest = self.longest.max(stretch);
        if stretch >= self.window_ticks && !self.in_livelock {
            self.in_livelock = true;
            self.livelocks += 1;
        }
    }

    fn progress(&mut self, tick: u64) {
        self.last_progress = self.last_progress.max(tick);
        self.in_livelock = false;
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

/// The length of `path` from the point on it nearest to `p` to its end.
fn length_left_along(path: &[[f32; 2]], p: (f64, f64)) -> f64 {
    let point = |q: [f32; 2]| (f64::from(q[0]), f64::from(q[1]));
    let (mut nearest, mut from, mut at) = (f64::INFINITY, 0, (0.0, 0.0));
    for (i, seg) in path.windows(2).enumerate() {
        let (a, b) = (point(seg[0]), point(seg[1]));
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let len2 = dx * dx + dy * dy;
        let u = if len2 > 0.0 {
            (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let q = (a.0 + u * dx, a.1 + u * dy);
        let d = (p.0 - q.0).hypot(p.1 - q.1);
        if d < nearest {
            (nearest, from, at) = (d, i + 1, q);
        }
    }
    let mut left = 0.0;
    let mut last = at;
    for &q in &path[from..] {
        let q = point(q);
        left += (q.0 - last.0).hypot(q.1 - last.1);
        last = q;
    }
    left
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A check every 10 steps at `position(tick)`, the status of each step with `target(tick)`.
    fn run(
        p: &mut Progress,
        ticks: std::ops::Range<u64>,
        target: impl Fn(u64) -> Option<(f64, f64)>,
        position: impl Fn(u64) -> (f64, f64),
        explored: impl Fn(u64) -> u64,
    ) {
        for tick in ticks {
            p.on_status(tick, target(tick), &[]);
            if tick % 10 == 0 {
                p.on_check(tick, explored(tick), position(tick));
            }
        }
    }

    /// Circling in front of a target it never reaches is a livelock, counted once however long
    /// it lasts; approaching the target or new area ends it.
    #[test]
    fn circling_before_a_target_is_a_livelock_and_progress_ends_it() {
        let mut p = Progress::new(0.1); // 300 steps make 30 s
        let goal = |_| Some((5.0, 0.0));
        let circle = |tick: u64| {
            let a = tick as f64 * 0.1;
            (1.0 + 0.3 * a.cos(), 0.3 * a.sin())
        };
        run(&mut p, 0..1000, goal, circle, |_| 0);
        assert_eq!(p.livelocks(), 1);
        assert!(p.longest_ticks() >= 980, "{}", p.longest_ticks());
        // It drives to the target, and finds new area there: no new livelock.
        let drive = |tick: u64| (1.0 + 0.01 * (tick - 1000) as f64, 0.0);
        run(&mut p, 1000..1400, goal, drive, |tick| tick / 100);
        assert_eq!(p.livelocks(), 1);
    }

    /// Switching between two targets without approaching either is no progress.
    #[test]
    fn switching_targets_for_ever_is_no_progress() {
        let mut p = Progress::new(0.1);
        let flip = |tick: u64| {
            Some(if tick % 20 < 10 {
                (5.0, 0.0)
            } else {
                (-5.0, 0.0)
            })
        };
        run(&mut p, 0..400, flip, |_| (0.0, 0.0), |_| 0);
        assert_eq!(p.livelocks(), 1);
        assert_eq!(p.longest_ticks(), 390);
    }

    /// New area at every check keeps a run out of livelock, with no target at all.
    #[test]
    fn new_area_is_progress_without_a_target() {
        let mut p = Progress::new(0.1);
        run(&mut p, 0..2000, |_| None, |_| (0.0, 0.0), |tick| tick / 10);
        assert_eq!(p.livelocks(), 0);
        assert!(p.longest_ticks() <= 10);
    }

    /// A check judged before its step's status arrived, or after, gives the same result: each
    /// check waits for the target of its own step. (Here the target switches at a check's step
    /// from one behind the robot to one ahead, so a check judged against the step before's
    /// target would start measuring the approach one check later.)
    #[test]
    fn the_order_of_grid_and_status_does_not_matter() {
        let target = |tick: u64| {
            Some(if tick < 500 {
                (-10.0, 0.0)
            } else {
                (10.0, 0.0)
            })
        };
        let position = |tick: u64| (0.004 * tick as f64, 0.0);
        let mut status_first = Progress::new(0.01);
        run(&mut status_first, 0..3000, target, position, |_| 0);
        let mut check_first = Progress::new(0.01);
        for tick in 0..3000 {
            if tick % 10 == 0 {
                check_first.on_check(tick, 0, position(tick));
            }
            // The status of each step three steps late.
            if let Some(late) = tick.checked_sub(3) {
                check_first.on_status(late, target(late), &[]);
            }
        }
        let (a, b) = (status_first.finished(), check_first.finished());
        assert_eq!(a.longest_ticks(), b.longest_ticks());
        // The approach is measured from step 500 on: 0.25 m closer at the check of step 570,
        // so the longest stretch without progress ended at the check before, 560.
        assert_eq!(a.longest_ticks(), 560);
    }

    /// A point `s` metres along the polyline `path`.
    fn along(path: &[[f32; 2]], s: f64) -> (f64, f64) {
        let mut left = s;
        for seg in path.windows(2) {
            let (a, b) = (seg[0].map(f64::from), seg[1].map(f64::from));
            let len = (b[0] - a[0]).hypot(b[1] - a[1]);
            if left <= len {
                let u = left / len;
                return (a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1]));
            }
            left -= len;
        }
        let end = path[path.len() - 1];
        (f64::from(end[0]), f64::from(end[1]))
    }

    /// A target 1 m away behind a wall, reached by a 19 m detour that leads away from it for
    /// 45 s, driven without a stop through known area, is no livelock: the approach is measured
    /// along the published path. (In a straight line it comes 0.25 m closer only after 45 s.)
    #[test]
    fn driving_a_detour_along_the_published_path_is_progress() {
        let path: [[f32; 2]; 5] = [[0.0, 0.0], [8.0, 0.0], [8.0, 2.0], [0.0, 2.0], [0.0, 1.0]];
        let mut p = Progress::new(0.1);
        for tick in 0..475u64 {
            p.on_status(tick, Some((0.0, 1.0)), &path);
            if tick % 10 == 0 {
                p.on_check(tick, 0, along(&path, 0.04 * tick as f64));
            }
        }
        assert_eq!(p.livelocks(), 0, "longest {}", p.longest_ticks());
        assert!(p.longest_ticks() <= 10, "{}", p.longest_ticks());
    }

    /// Circling in front of a gap with a path through it is a livelock all the same: the
    /// length left along the path never shrinks.
    #[test]
    fn circling_before_a_path_is_a_livelock() {
        let path: [[f32; 2]; 3] = [[0.0, 0.0], [2.0, 0.0], [5.0, 0.0]];
        let mut p = Progress::new(0.1);
        for tick in 0..400u64 {
            p.on_status(tick, Some((5.0, 0.0)), &path);
            if tick % 10 == 0 {
                let a = tick as f64 * 0.1;
                p.on_check(tick, 0, (1.0 + 0.3 * a.cos(), 0.3 * a.sin()));
            }
        }
        assert_eq!(p.livelocks(), 1);
    }

    /// The length left is measured from the nearest point on the path, wherever the robot is.
    #[test]
    fn the_length_left_is_from_the_nearest_point_of_the_path() {
        let path: [[f32; 2]; 3] = [[0.0, 0.0], [4.0, 0.0], [4.0, 3.0]];
        assert!((length_left_along(&path, (1.0, 0.5)) - 6.0).abs() < 1e-9);
        assert!((length_left_along(&path, (4.5, 1.0)) - 2.0).abs() < 1e-9);
        assert!((length_left_along(&path, (-1.0, 0.0)) - 7.0).abs() < 1e-9);
        assert!(length_left_along(&path, (9.0, 9.0)).abs() < 1e-9);
    }
}
