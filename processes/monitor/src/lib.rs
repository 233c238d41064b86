//! Monitor: metrics against ground truth, summary.json and map.png.
//!
//! The monitor process subscribes to every topic and feeds each message to a [`Monitor`]; a few
//! times a second it publishes [`Monitor::write_status`], and when the run ends it writes
//! [`Monitor::summary`] with [`write_summary`] and the picture with [`Monitor::render_png`].
//! Everything is judged against the ground truth of `world/map` rasterised at the mapping grid's
//! resolution. Per-message methods never allocate: every buffer is sized in [`Monitor::new`].

mod ending;
mod particles;
mod progress;
mod render;
mod slam;
mod smoothed;
mod summary;
mod track;
mod truth;

pub use ending::{Ending, LOCKSTEP_DRAIN, RunEnding};
pub use progress::{LIVELOCK_S, Progress};
pub use slam::{CHI2_2_95, SlamSummary, mean_nees_interval, mean_nees_interval_of_dof, nees_2d};
pub use summary::{
    FaultRecord, LatencyUs, RunMeta, Summary, SwapRecord, TopicSummary, UpdateUs, fnv1a64,
    read_summary, write_summary,
};

use hdrhistogram::Histogram;
use mole_types::{
    BeaconSite, CELL_FREE, CELL_OCCUPIED, DIRECTION_SUBSCRIBE, EndReason, EstimatorKind,
    GRID_CONTACT, GRID_FRONTIER, Grid, Invalid, Landmarks, MAX_PARTICLES, MAX_PATH,
    MAX_TOPIC_STATS, MODE_STALLED, Message, NAME_LEN, Particles, PlanStatus, Pose, RunStatus,
    STATUS_EXPLORATION_COMPLETE, STATUS_HAS_FRONTIER, STATUS_HAS_GOAL, Square, Stats,
    TRUTH_GOAL_REACHED, TRUTH_IN_CONTACT, TopicStats, Trajectory, Truth, WorldMap, read_name,
    wrap_angle,
};
use particles::ParticleCounts;
pub use particles::ParticleSummary;
use slam::LandmarkMap;
use smoothed::SmoothedTrajectory;
use std::cell::Cell;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use track::Track;
use truth::{NEAR_OCCUPIED, OCCUPIED, REACHABLE, TruthRaster};

/// Most points kept of each trajectory (true and estimated); longer runs are decimated.
pub const MAX_TRACK_POINTS: usize = 20_000;
/// Recent truths kept to match poses of the same tick.
const TRUTH_RING: usize = 256;
/// Poses kept while they wait for the truth of their tick.
const POSE_RING: usize = 64;
/// Distinct (process, pid) pairs whose statistics the monitor keeps (restarts included).
pub const MAX_PROCESSES: usize = 64;
/// Highest latency the histograms track (ns); larger values are clamped.
const HIST_MAX_NS: u64 = 60_000_000_000;

/// Why the monitor could not start or write its output.
#[derive(Debug, thiserror::Error)]
pub enum MonitorError {
    /// The world map failed validation.
    #[error("invalid world map: {0}")]
    InvalidMap(#[from] Invalid),
    /// The arena at the grid resolution needs more cells than a grid message holds.
    #[error("arena needs {width} × {height} cells, more than a grid message holds")]
    GridTooLarge { width: f64, height: f64 },
    /// A latency histogram could not be created.
    #[error("histogram: {0}")]
    Histogram(#[from] hdrhistogram::CreationError),
    /// Writing an output file failed.
    #[error("cannot write {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// Serialising the summary failed.
    #[error("summary serialisation: {0}")]
    Json(#[from] serde_json::Error),
    /// Encoding map.png failed.
    #[error("png encoding: {0}")]
    Png(#[from] png::EncodingError),
}

/// One truth kept for matching poses.
#[derive(Debug, Clone, Copy, Default)]
struct TruthSample {
    valid: bool,
    tick: u64,
    x: f64,
    y: f64,
    theta: f64,
}

/// One pose waiting for its truth.
#[derive(Debug, Clone, Copy, Default)]
struct PoseSample {
    valid: bool,
    tick: u64,
    x: f64,
    y: f64,
    theta: f64,
    covariance: [f64; 9],
}

/// The latest statistics of one process instance.
#[derive(Debug, Clone, Copy)]
struct ProcessStats {
    process: [u8; NAME_LEN],
    pid: u32,
    n_topics: usize,
    topics: [TopicStats; MAX_TOPIC_STATS],
}

/// A grid as last received, in the monitor's own layout (the truth raster's).
#[derive(Debug, Clone)]
struct LatestGrid {
    cells: Vec<u8>,
    received: bool,
}

/// What the world map says, kept for the summary and the picture.
#[derive(Debug, Clone)]
pub(crate) struct Scene {
    pub arena_width: f64,
    pub arena_height: f64,
    pub dt: f64,
    pub start: (f64, f64),
    pub goal: Option<(f64, f64)>,
    pub goal_tolerance: f64,
    pub squares: Vec<Square>,
    pub beacons: Vec<BeaconSite>,
}

/// Coverage fractions whose first step the summary reports (`coverage_steps`).
pub const COVERAGE_MILESTONES: [f64; 4] = [0.5, 0.9, 0.95, 0.99];

/// Coverage milestones are checked on the grids of every this many steps (0.1 s at 100 Hz) and
/// on the last one; the grid scores are otherwise computed when asked for. Scanning both grids
/// at every step was a third of the monitor's CPU in lockstep.
pub const COVERAGE_EVERY: u64 = 10;

/// Scores of the frontier grid against the truth raster (see [`Monitor::on_grid`]).
#[derive(Debug, Clone, Copy, Default)]
struct GridScore {
    explored_reachable: u64,
    iou_intersection: u64,
    iou_union: u64,
}

/// Scores of the contact grid against the truth raster (see [`Monitor::on_contact`]).
#[derive(Debug, Clone, Copy, Default)]
struct ContactScore {
    cells: u64,
    near_occupied: u64,
}

/// The observer: ground truth from `world/map`, fed every other message as it arrives.
pub struct Monitor {
    scene: Scene,
    raster: TruthRaster,

    grid: LatestGrid,
    /// The score of `grid`, computed when first asked for (`None`: not yet).
    grid_score: Cell<Option<GridScore>>,
    /// Step at which coverage first reached each of [`COVERAGE_MILESTONES`].
    coverage_steps: [Option<u64>; COVERAGE_MILESTONES.len()],
    /// The tick of `grid`.
    grid_tick: u64,
    contact: LatestGrid,
    contact_score: Cell<Option<ContactScore>>,
    ignored_messages: u64,

    true_track: Track,
    est_track: Track,
    last_truth: Option<(u64, f64, f64)>,
    path_length: f64,
    max_penetration: f64,
    loop_latency_ns: Histogram<u64>,
    goal_tick: Option<u64>,
    in_contact: bool,
    contact_events: u64,
    contact_ticks: u64,
    last_tick: u64,
    ended: bool,
    end_reason: u32,

    truths: Vec<TruthSample>,
    poses: Vec<PoseSample>,
    squared_error_sum: f64,
    pose_samples: u64,
    nees_sum: f64,
    nees_samples: u64,
    estimator: Option<u32>,
    update_ns: Histogram<u64>,

    particles: Vec<[f32; 2]>,
    /// The particle filter's set size over the run.
    particle_counts: ParticleCounts,
    landmarks: LandmarkMap,
    smoothed: SmoothedTrajectory,

    stats: Vec<ProcessStats>,

    plan_mode: u32,
    /// Times the planner reported a stall (MODE_STALLED).
    stalls: u32,
    /// New area or an approach to the planner's target, or neither (a livelock).
    progress: Progress,
    bounces: u32,
    /// Frontier targets the planner gave up so far (`PlanStatus::give_ups`).
    give_ups: u32,
    exploration_complete: bool,
    plan_path: Vec<[f32; 2]>,
}

impl Monitor {
    /// From world/map (ground truth: arena, squares, start, goal, robot radius, grid
    /// resolution). Rasterises the true occupancy at the grid resolution (a cell is occupied if
    /// a square or the outside overlaps it with positive area) and flood-fills the cells the
    /// robot centre can reach from the start (free cells whose distance to every occupied cell
    /// exceeds the robot radius − half a cell, the distance to a cell measured to its near edge
    /// as centre-to-centre minus half a cell; 8-connected) = the reachable free area. Cells
    /// outside the arena count as occupied. Preallocates everything.
    pub fn new(map: &WorldMap) -> Result<Monitor, MonitorError> {
        map.validate()?;
        let raster = TruthRaster::new(map)?;
        let n = raster.width * raster.height;
        let hist = || Histogram::<u64>::new_with_bounds(1, HIST_MAX_NS, 3);
        Ok(Monitor {
            scene: Scene {
                arena_width: map.arena_width,
                arena_height: map.arena_height,
                dt: map.dt,
                start: (map.start_x, map.start_y),
                goal: (map.has_goal == 1).then_some((map.goal_x, map.goal_y)),
                goal_tolerance: map.goal_tolerance,
                squares: map.obstacles().to_vec(),
                beacons: map.beacons().to_vec(),
            },
            raster,
            grid: LatestGrid {
                cells: vec![0; n],
                received: false,
            },
            grid_score: Cell::new(None),
            coverage_steps: [None; COVERAGE_MILESTONES.len()],
            grid_tick: 0,
            contact: LatestGrid {
                cells: vec![0; n],
                received: false,
            },
            contact_score: Cell::new(None),
            ignored_messages: 0,
            true_track: Track::new(MAX_TRACK_POINTS),
            est_track: Track::new(MAX_TRACK_POINTS),
            last_truth: None,
            path_length: 0.0,
            max_penetration: 0.0,
            loop_latency_ns: hist()?,
            goal_tick: None,
            in_contact: false,
            contact_events: 0,
            contact_ticks: 0,
            last_tick: 0,
            ended: false,
            end_reason: 0,
            truths: vec![TruthSample::default(); TRUTH_RING],
            poses: vec![PoseSample::default(); POSE_RING],
            squared_error_sum: 0.0,
            pose_samples: 0,
            nees_sum: 0.0,
            nees_samples: 0,
            estimator: None,
            update_ns: hist()?,
            particles: Vec::with_capacity(MAX_PARTICLES),
            particle_counts: ParticleCounts::default(),
            landmarks: LandmarkMap::new(),
            smoothed: SmoothedTrajectory::new(),
            stats: Vec::with_capacity(MAX_PROCESSES),
            plan_mode: 0,
            stalls: 0,
            progress: Progress::new(map.dt),
            bounces: 0,
            give_ups: 0,
            exploration_complete: false,
            plan_path: Vec::with_capacity(MAX_PATH),
        })
    }

    /// Grid cells along x and y that the monitor expects (`ceil(W/res)`, `ceil(H/res)`).
    pub fn grid_size(&self) -> (u32, u32) {
        (self.raster.width as u32, self.raster.height as u32)
    }

    /// Free cells the robot centre can reach from the start (the coverage denominator).
    pub fn reachable_free_cells(&self) -> u64 {
        self.raster.reachable_free
    }

    /// Grids refused (size, resolution, origin, kind) plus stats beyond capacity.
    pub fn ignored_messages(&self) -> u64 {
        self.ignored_messages
    }

    /// Whether a truth with the end flag has arrived.
    pub fn ended(&self) -> bool {
        self.ended
    }

    /// Takes one ground-truth step: trajectory (decimated), path length, max penetration, loop
    /// latency (`cmd_latency_ns` when > 0), goal reached and its time (tick·dt), contacts, last
    /// tick, end flag and reason.
    pub fn on_truth(&mut self, truth: &Truth) {
        let tick = truth.header.tick;
        self.true_track.push(truth.x, truth.y);
        match self.last_truth {
            Some((last, x, y)) if tick > last => {
                self.path_length += (truth.x - x).hypot(truth.y - y);
            }
            // A repeated tick adds nothing; an older tick (a restarted world) starts a new leg.
            _ => {}
        }
        self.last_truth = Some((tick, truth.x, truth.y));
        self.last_tick = self.last_tick.max(tick);
        if truth.penetration > self.max_penetration {
            self.max_penetration = truth.penetration;
        }
        if truth.cmd_latency_ns > 0 {
            self.loop_latency_ns.saturating_record(truth.cmd_latency_ns);
        }
        if truth.flags & TRUTH_GOAL_REACHED != 0 && self.goal_tick.is_none() {
            self.goal_tick = Some(tick);
        }
        let touching = truth.flags & TRUTH_IN_CONTACT != 0 || truth.n_contacts > 0;
        if touching {
            self.contact_ticks += 1;
            if !self.in_contact {
                self.contact_events += 1;
            }
        }
        self.in_contact = touching;
        if truth.is_end() {
            self.ended = true;
            self.end_reason = truth.end_reason;
        }

        let sample = TruthSample {
            valid: true,
            tick,
            x: truth.x,
            y: truth.y,
            theta: truth.theta,
        };
        self.truths[(tick % TRUTH_RING as u64) as usize] = sample;
        self.smoothed.on_truth(tick, truth.x, truth.y);
        let waiting = self.poses[(tick % POSE_RING as u64) as usize];
        if waiting.valid && waiting.tick == tick {
            self.poses[(tick % POSE_RING as u64) as usize].valid = false;
            self.score(&waiting, &sample);
        }
    }

    /// Takes one pose estimate: matched to the truth of the same tick (now, or when that truth
    /// arrives) for the RMSE and the NEES; estimated trajectory, estimator id, update time.
    pub fn on_pose(&mut self, pose: &Pose) {
        let tick = pose.header.tick;
        self.estimator = Some(pose.estimator);
        self.update_ns.saturating_record(pose.update_ns);
        self.est_track.push(pose.x, pose.y);
        self.smoothed.on_filter(tick, pose.x, pose.y);
        let sample = PoseSample {
            valid: true,
            tick,
            x: pose.x,
            y: pose.y,
            theta: pose.theta,
            covariance: pose.covariance,
        };
        let truth = self.truths[(tick % TRUTH_RING as u64) as usize];
        if truth.valid && truth.tick == tick {
            self.score(&sample, &truth);
        } else {
            self.poses[(tick % POSE_RING as u64) as usize] = sample;
        }
    }

    /// Squared position error for the RMSE and, when Σ is positive definite, the NEES
    /// eᵀΣ⁻¹e of e = (Δx, Δy, wrap(Δθ)) (Bar-Shalom, Li & Kirubarajan, "Estimation with
    /// Applications to Tracking and Navigation", §5.4).
    fn score(&mut self, pose: &PoseSample, truth: &TruthSample) {
        let e = [
            pose.x - truth.x,
            pose.y - truth.y,
            wrap_angle(pose.theta - truth.theta),
        ];
        let sq = e[0] * e[0] + e[1] * e[1];
        if !sq.is_finite() {
            return;
        }
        self.squared_error_sum += sq;
        self.pose_samples += 1;
        if let Some(nees) = nees(&e, &pose.covariance) {
            self.nees_sum += nees;
            self.nees_samples += 1;
        }
    }

    /// Takes a frontier grid (kind `GRID_FRONTIER`): keeps its cells for coverage and IoU, and
    /// every [`COVERAGE_EVERY`] steps records whether coverage first reached one of
    /// [`COVERAGE_MILESTONES`]. A grid of another kind, size, resolution or origin is ignored
    /// and counted.
    pub fn on_grid(&mut self, grid: &Grid) {
        if grid.kind != GRID_FRONTIER || !self.accept(grid, false) {
            self.ignored_messages += 1;
            return;
        }
        self.grid_tick = grid.header.tick;
        self.grid_score.set(None);
        if grid.header.tick.is_multiple_of(COVERAGE_EVERY) {
            self.record_milestones();
        }
    }

    /// Marks the milestones the current grid's coverage reached first.
    fn record_milestones(&mut self) {
        self.coverage_steps = self.milestones();
        let explored = self.grid_score().explored_reachable;
        let tick = self.grid_tick;
        let truth = self.truths[(tick % TRUTH_RING as u64) as usize];
        let position = match self.last_truth {
            _ if truth.valid && truth.tick == tick => (truth.x, truth.y),
            Some((_, x, y)) => (x, y),
            None => self.scene.start,
        };
        self.progress.on_check(tick, explored, position);
    }

    /// The recorded milestones, and those the current grid reaches.
    fn milestones(&self) -> [Option<u64>; COVERAGE_MILESTONES.len()] {
        let coverage = self.coverage();
        let mut steps = self.coverage_steps;
        for (milestone, threshold) in steps.iter_mut().zip(COVERAGE_MILESTONES) {
            if milestone.is_none() && self.grid.received && coverage >= threshold {
                *milestone = Some(self.grid_tick);
            }
        }
        steps
    }

    /// The frontier grid's score, scanned once per grid (branch-free over 64-cell chunks in
    /// u32 lanes, so it vectorises).
    fn grid_score(&self) -> GridScore {
        if let Some(score) = self.grid_score.get() {
            return score;
        }
        let mut score = GridScore::default();
        for (cells, flags) in self.grid.cells.chunks(64).zip(self.raster.flags.chunks(64)) {
            let (mut reach, mut both, mut either) = (0u32, 0u32, 0u32);
            for (&cell, &flag) in cells.iter().zip(flags) {
                let explored = u32::from(cell == CELL_FREE) | u32::from(cell == CELL_OCCUPIED);
                let predicted = u32::from(cell == CELL_OCCUPIED);
                let actual = u32::from(flag & OCCUPIED != 0) & explored;
                reach += explored & u32::from(flag & REACHABLE != 0);
                both += predicted & actual;
                either += predicted | actual;
            }
            score.explored_reachable += u64::from(reach);
            score.iou_intersection += u64::from(both);
            score.iou_union += u64::from(either);
        }
        self.grid_score.set(Some(score));
        score
    }

    /// Takes a contact grid (kind `GRID_CONTACT`) for the contact map's precision; other
    /// grids are ignored and counted like in [`Monitor::on_grid`].
    pub fn on_contact(&mut self, grid: &Grid) {
        if grid.kind != GRID_CONTACT || !self.accept(grid, true) {
            self.ignored_messages += 1;
            return;
        }
        self.contact_score.set(None);
    }

    /// The contact grid's score, scanned once per grid.
    fn contact_score(&self) -> ContactScore {
        if let Some(score) = self.contact_score.get() {
            return score;
        }
        let mut score = ContactScore::default();
        for (chunk, flags) in self
            .contact
            .cells
            .chunks(64)
            .zip(self.raster.flags.chunks(64))
        {
            let (mut c, mut n) = (0u32, 0u32);
            for (&cell, &flag) in chunk.iter().zip(flags) {
                let occupied = u32::from(cell == 1);
                c += occupied;
                n += occupied & u32::from(flag & NEAR_OCCUPIED != 0);
            }
            score.cells += u64::from(c);
            score.near_occupied += u64::from(n);
        }
        self.contact_score.set(Some(score));
        score
    }

    /// Copies a grid into the monitor's layout when it matches the truth raster: same
    /// resolution, origin (0, 0), and each dimension equal to the expected one or off by one
    /// (mapping may round `W/res` up where the monitor forgives floating-point noise); the
    /// overlapping cells are copied, the rest read 0.
    fn accept(&mut self, grid: &Grid, contact: bool) -> bool {
        let res = self.raster.resolution;
        let (w, h) = (self.raster.width, self.raster.height);
        let (gw, gh) = (grid.width as usize, grid.height as usize);
        let fits = (grid.resolution - res).abs() <= 1e-6 * res
            && grid.origin_x.abs() <= 1e-3 * res
            && grid.origin_y.abs() <= 1e-3 * res
            && gw.abs_diff(w) <= 1
            && gh.abs_diff(h) <= 1
            && gw * gh == grid.cells().len();
        if !fits {
            return false;
        }
        let target = if contact {
            &mut self.contact
        } else {
            &mut self.grid
        };
        let cells = grid.cells();
        if gw == w && gh == h {
            target.cells.copy_from_slice(cells);
        } else {
            target.cells.fill(0);
            let (cw, ch) = (w.min(gw), h.min(gh));
            for row in 0..ch {
                target.cells[row * w..row * w + cw]
                    .copy_from_slice(&cells[row * gw..row * gw + cw]);
            }
        }
        target.received = true;
        true
    }

    /// Keeps the latest particle cloud (positions only) for the picture.
    pub fn on_particles(&mut self, p: &Particles) {
        self.particle_counts.record(p.header.tick, p.n_filter);
        self.particles.clear();
        self.particles
            .extend(p.particles().iter().map(|q| [q.x, q.y]));
    }

    /// Keeps the latest landmark map of a SLAM estimator, scored at the end against the true
    /// beacons and drawn with its 95% ellipses.
    pub fn on_landmarks(&mut self, map: &Landmarks) {
        self.landmarks.on_landmarks(map);
    }

    /// Takes a smoother's trajectory (GraphSLAM): scored at once against the truth, beside the
    /// filter's poses of the same ticks, and kept for map.png.
    pub fn on_trajectory(&mut self, trajectory: &Trajectory) {
        self.smoothed.on_trajectory(trajectory);
    }

    /// The SLAM section: the last landmark map scored against the true beacons, and the newest
    /// smoothed trajectory against the truth and the filter; `None` unless the estimator is a
    /// SLAM one or a landmark map arrived.
    pub fn slam(&self) -> Option<SlamSummary> {
        let slam_estimator = self
            .estimator
            .and_then(EstimatorKind::from_code)
            .is_some_and(EstimatorKind::is_slam);
        (slam_estimator || self.landmarks.received()).then(|| {
            let mut section = self.landmarks.score(&self.scene.beacons);
            self.smoothed.fill(&mut section);
            section
        })
    }

    /// Keeps the latest counters of one process instance (by role and pid, so a restarted
    /// process's counters add to its predecessor's). Beyond [`MAX_PROCESSES`] instances the
    /// message is ignored and counted.
    pub fn on_stats(&mut self, stats: &Stats) {
        let n_topics = stats.topics().len();
        let slot = self
            .stats
            .iter()
            .position(|s| s.process == stats.process && s.pid == stats.pid);
        let entry = match slot {
            Some(i) => &mut self.stats[i],
            None if self.stats.len() < MAX_PROCESSES => {
                self.stats.push(ProcessStats {
                    process: stats.process,
                    pid: stats.pid,
                    n_topics: 0,
                    topics: [TopicStats::default(); MAX_TOPIC_STATS],
                });
                let last = self.stats.len() - 1;
                &mut self.stats[last]
            }
            None => {
                self.ignored_messages += 1;
                return;
            }
        };
        entry.n_topics = n_topics;
        entry.topics[..n_topics].copy_from_slice(stats.topics());
    }

    /// Keeps the planner's mode, bounce count, exploration-complete flag and path.
    pub fn on_plan_status(&mut self, s: &PlanStatus) {
        // A local minimum the planner reported (algorithms §1 APF): count each entry into the mode.
        if s.mode == MODE_STALLED && self.plan_mode != MODE_STALLED {
            self.stalls += 1;
        }
        self.plan_mode = s.mode;
        self.bounces = s.bounces;
        self.give_ups = s.give_ups;
        self.exploration_complete |= s.flags & STATUS_EXPLORATION_COMPLETE != 0;
        let target = if s.flags & STATUS_HAS_FRONTIER != 0 {
            Some((s.frontier_x, s.frontier_y))
        } else if s.flags & STATUS_HAS_GOAL != 0 {
            Some((s.goal_x, s.goal_y))
        } else {
            None
        };
        self.progress.on_status(s.header.tick, target, s.path());
        self.plan_path.clear();
        self.plan_path.extend_from_slice(s.path());
    }

    /// Fraction of the reachable free cells that the frontier grid marks explored (1 or 2);
    /// 0 before any grid or when nothing is reachable.
    pub fn coverage(&self) -> f64 {
        if self.raster.reachable_free == 0 {
            return 0.0;
        }
        self.grid_score().explored_reachable as f64 / self.raster.reachable_free as f64
    }

    /// Contact cells (1) that lie within one cell (8-neighbourhood, the cell itself included)
    /// of a truly occupied cell or of the arena's outside, over all contact cells: contact
    /// points lie on obstacle boundaries, so they may fall in the free cell next to one. `None`
    /// when there is no contact cell.
    pub fn contact_map_precision(&self) -> Option<f64> {
        let score = self.contact_score();
        (score.cells > 0).then(|| score.near_occupied as f64 / score.cells as f64)
    }

    /// Intersection over union of "occupied" between the frontier grid (cells = 2) and the
    /// truth raster (a square or the outside overlaps the cell), counted only over the cells the
    /// grid has explored (1 or 2): unexplored space is not a penalty, coverage measures that.
    /// `None` before any grid, or while the union is empty (no occupied cell on either side
    /// among the explored ones, so the ratio is undefined).
    pub fn map_iou(&self) -> Option<f64> {
        let score = self.grid_score();
        (self.grid.received && score.iou_union > 0)
            .then(|| score.iou_intersection as f64 / score.iou_union as f64)
    }

    /// √(mean of (Δx² + Δy²)) over poses matched to the truth of their tick; `None` before any.
    pub fn localization_rmse(&self) -> Option<f64> {
        (self.pose_samples > 0).then(|| (self.squared_error_sum / self.pose_samples as f64).sqrt())
    }

    /// Mean NEES over (x, y, θ) (3 for a consistent estimator); `None` before any sample.
    pub fn mean_nees(&self) -> Option<f64> {
        (self.nees_samples > 0).then(|| self.nees_sum / self.nees_samples as f64)
    }

    /// Path length of the true trajectory so far (m).
    pub fn path_length(&self) -> f64 {
        self.path_length
    }

    /// Loop latency quantile (µs), `None` before any command latency.
    pub fn loop_latency_us(&self, quantile: f64) -> Option<f64> {
        quantile_us(&self.loop_latency_ns, quantile)
    }

    /// Fills the live status: everything but the header; `finished` is written 0 (the process
    /// sets it once the files are written). Unknown values (no latency, no RMSE yet) read 0.
    pub fn write_status(&self, out: &mut RunStatus) {
        out.coverage = self.coverage() as f32;
        out.loop_p50_us = self.loop_latency_us(0.5).unwrap_or(0.0) as f32;
        out.loop_p99_us = self.loop_latency_us(0.99).unwrap_or(0.0) as f32;
        out.max_penetration_m = self.max_penetration as f32;
        out.rmse_m = self.localization_rmse().unwrap_or(0.0) as f32;
        out.finished = 0;
    }

    /// Per topic name over every process instance: the highest subscriber-side rate (the
    /// publisher rate when no subscriber reported it), drops and invalid counts summed.
    fn topic_summaries(&self) -> BTreeMap<String, TopicSummary> {
        let mut out: BTreeMap<String, (TopicSummary, bool, f64)> = BTreeMap::new();
        for process in &self.stats {
            for t in &process.topics[..process.n_topics] {
                let name = read_name(&t.topic);
                if name.is_empty() {
                    continue;
                }
                let (sum, has_sub, pub_rate) = out.entry(name.into_owned()).or_default();
                sum.dropped = sum.dropped.saturating_add(t.dropped);
                sum.invalid = sum.invalid.saturating_add(t.invalid);
                let rate = f64::from(t.rate_hz);
                if t.direction == DIRECTION_SUBSCRIBE {
                    *has_sub = true;
                    sum.rate_hz = sum.rate_hz.max(rate);
                } else {
                    *pub_rate = pub_rate.max(rate);
                }
            }
        }
        out.into_iter()
            .map(|(name, (mut sum, has_sub, pub_rate))| {
                if !has_sub {
                    sum.rate_hz = pub_rate;
                }
                (name, sum)
            })
            .collect()
    }

    /// The fields README.md lists for summary.json plus NEES, estimator update time, bounces, grid
    /// hashes and the reachable free cells; `meta` supplies what the monitor cannot see.
    pub fn summary(&self, meta: &RunMeta) -> Summary {
        let finite = |v: f64| if v.is_finite() { v } else { 0.0 };
        let hash = |g: &LatestGrid| g.received.then(|| format!("{:016x}", fnv1a64(&g.cells)));
        let progress = self.progress.finished();
        Summary {
            ticks: self.last_tick,
            sim_time_s: finite(self.last_tick as f64 * self.scene.dt),
            wall_time_s: finite(meta.wall_time_s),
            planner: meta.planner.clone(),
            estimator: meta.estimator.clone(),
            mode: meta.mode.clone(),
            seed: meta.seed,
            goal_reached: self.goal_tick.is_some(),
            time_to_goal_s: self.goal_tick.map(|t| t as f64 * self.scene.dt),
            path_length_m: finite(self.path_length),
            coverage: self.coverage(),
            contact_map_precision: self.contact_map_precision(),
            map_iou: self.map_iou(),
            localization_rmse_m: self.localization_rmse().filter(|v| v.is_finite()),
            max_penetration_m: finite(self.max_penetration),
            loop_latency_us: LatencyUs {
                p50: self.loop_latency_us(0.5),
                p99: self.loop_latency_us(0.99),
                max: self.loop_latency_us(1.0),
                histogram: histogram_us(&self.loop_latency_ns),
            },
            topics: self.topic_summaries(),
            restarts: meta.restarts.clone(),
            exit_reason: meta.exit_reason.clone(),
            mean_nees: self.mean_nees().filter(|v| v.is_finite()),
            estimator_update_us: UpdateUs {
                p50: quantile_us(&self.update_ns, 0.5),
                p99: quantile_us(&self.update_ns, 0.99),
            },
            bounces: self.bounces,
            give_ups: self.give_ups,
            stalls: self.stalls,
            longest_without_progress_s: finite(progress.longest_ticks() as f64 * self.scene.dt),
            livelocks: progress.livelocks(),
            grid_hash: hash(&self.grid),
            contact_hash: hash(&self.contact),
            reachable_free_cells: self.raster.reachable_free,
            coverage_steps: COVERAGE_MILESTONES
                .iter()
                .zip(self.milestones())
                .map(|(t, step)| (t.to_string(), step))
                .collect(),
            end_reason: self
                .ended
                .then(|| end_reason_name(self.end_reason).to_owned()),
            // The world ends the run on the planner's MODE_DONE, possibly before the monitor
            // reads the status that carries the flag: that end is the planner's word too.
            exploration_complete: self.exploration_complete
                || (self.ended
                    && EndReason::from_code(self.end_reason)
                        == Some(EndReason::ExplorationComplete)),
            contact_events: self.contact_events,
            contact_ticks: self.contact_ticks,
            pose_samples: self.pose_samples,
            nees_samples: self.nees_samples,
            ignored_messages: self.ignored_messages,
            slam: self.slam(),
            particles: self.particle_counts.summary(),
            // The launcher's part: it fills these after the run.
            hangs: BTreeMap::new(),
            swaps: Vec::new(),
            faults: Vec::new(),
            launcher_wall_time_s: None,
            settings: serde_json::Value::Null,
            settings_changes: serde_json::Value::Null,
        }
    }

    /// Size in pixels of the picture [`Monitor::render_png`] writes (width ≥ 800).
    pub fn image_size(&self) -> (u32, u32) {
        let layout = render::Layout::new(&self.scene);
        (layout.width as u32, layout.height as u32)
    }

    /// Writes map.png: frontier grid (unexplored dark grey, free light grey, occupied black),
    /// contact cells (red), true obstacle outlines (blue), planned path (gold), particle cloud
    /// (purple), true trajectory (green), estimated trajectory (orange), smoothed trajectory
    /// (azure), true beacons and landmark ellipses, start (cyan) and goal
    /// (magenta) markers, and a legend in a built-in bitmap font. At least 800 px wide, y up.
    /// summary.json and map.png in `out`, at the end of the run.
    pub fn write_files(&self, meta: &RunMeta, out: &Path) -> Result<(), MonitorError> {
        let io = |source| MonitorError::Io {
            path: out.to_path_buf(),
            source,
        };
        std::fs::create_dir_all(out).map_err(io)?;
        write_summary(&self.summary(meta), &out.join("summary.json"))?;
        self.render_png(&out.join("map.png"))?;
        tracing::info!(out = %out.display(), exit_reason = meta.exit_reason, "summary written");
        Ok(())
    }

    pub fn render_png(&self, path: &Path) -> Result<(), MonitorError> {
        let canvas = render::draw(self);
        let io = |source| MonitorError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = std::fs::File::create(path).map_err(io)?;
        let mut encoder = png::Encoder::new(
            std::io::BufWriter::new(file),
            canvas.width as u32,
            canvas.height as u32,
        );
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header()?;
        writer.write_image_data(&canvas.rgb)?;
        writer.finish()?;
        Ok(())
    }
}

/// A histogram quantile converted from ns to µs; `None` when empty.
fn quantile_us(h: &Histogram<u64>, quantile: f64) -> Option<f64> {
    (!h.is_empty()).then(|| h.value_at_quantile(quantile) as f64 / 1000.0)
}

/// eᵀΣ⁻¹e through the Cholesky factor of Σ's symmetric part; `None` unless Σ is positive
/// definite.
fn nees(e: &[f64; 3], cov: &[f64; 9]) -> Option<f64> {
    let s = |i: usize, j: usize| 0.5 * (cov[3 * i + j] + cov[3 * j + i]);
    // √v of a positive pivot; `None` for zero, negative or NaN (Σ not positive definite).
    let pivot = |v: f64| (v > 0.0).then(|| v.sqrt());
    let l11 = pivot(s(0, 0))?;
    let l21 = s(1, 0) / l11;
    let l31 = s(2, 0) / l11;
    let l22 = pivot(s(1, 1) - l21 * l21)?;
    let l32 = (s(2, 1) - l31 * l21) / l22;
    let l33 = pivot(s(2, 2) - l31 * l31 - l32 * l32)?;
    let y1 = e[0] / l11;
    let y2 = (e[1] - l21 * y1) / l22;
    let y3 = (e[2] - l31 * y1 - l32 * y2) / l33;
    let v = y1 * y1 + y2 * y2 + y3 * y3;
    v.is_finite().then_some(v)
}

/// The summary's name of a `Truth::end_reason` code.
fn end_reason_name(code: u32) -> &'static str {
    EndReason::from_code(code).map_or("none", EndReason::name)
}

impl Monitor {
    pub(crate) fn scene(&self) -> &Scene {
        &self.scene
    }
    pub(crate) fn raster_size(&self) -> (usize, usize, f64) {
        (
            self.raster.width,
            self.raster.height,
            self.raster.resolution,
        )
    }
    pub(crate) fn frontier_cells(&self) -> Option<&[u8]> {
        self.grid.received.then_some(&self.grid.cells[..])
    }
    pub(crate) fn contact_cells(&self) -> Option<&[u8]> {
        self.contact.received.then_some(&self.contact.cells[..])
    }
    pub(crate) fn true_points(&self) -> impl Iterator<Item = [f32; 2]> + '_ {
        self.true_track.points()
    }
    pub(crate) fn estimated_points(&self) -> impl Iterator<Item = [f32; 2]> + '_ {
        self.est_track.points()
    }
    pub(crate) fn particle_points(&self) -> &[[f32; 2]] {
        &self.particles
    }
    pub(crate) fn smoothed_points(&self) -> &[[f32; 2]] {
        self.smoothed.points()
    }
    pub(crate) fn landmark_estimates(&self) -> &[mole_types::Landmark] {
        self.landmarks.landmarks()
    }
    pub(crate) fn plan_points(&self) -> &[[f32; 2]] {
        &self.plan_path
    }
    pub(crate) fn status_lines(&self) -> [String; 3] {
        let fmt = |v: Option<f64>| v.map_or_else(|| "-".to_owned(), |v| format!("{v:.3}"));
        [
            format!("COVERAGE {:.1}%", 100.0 * self.coverage()),
            format!("RMSE {} M", fmt(self.localization_rmse())),
            format!("TICKS {}", self.last_tick),
        ]
    }
    /// The planner's mode code at its last status.
    pub fn plan_mode(&self) -> u32 {
        self.plan_mode
    }
}

#[cfg(test)]
mod tests;

/// A nanosecond histogram as `[upper bound (µs), count]` per doubling bucket from 1 µs.
fn histogram_us(h: &Histogram<u64>) -> Vec<[f64; 2]> {
    if h.is_empty() {
        return Vec::new();
    }
    h.iter_log(1000, 2.0)
        .map(|v| {
            [
                v.value_iterated_to() as f64 / 1000.0,
                v.count_since_last_iteration() as f64,
            ]
        })
        .collect()
}

impl RunMeta {
    /// What the monitor knows of the run when it ends (the launcher adds restarts).
    pub fn new(
        planner: mole_types::PlannerKind,
        estimator: mole_types::EstimatorKind,
        mode: mole_types::ClockMode,
        seed: u64,
        wall_time: std::time::Duration,
        exit_reason: &str,
    ) -> RunMeta {
        RunMeta {
            planner: planner.to_string(),
            estimator: estimator.to_string(),
            mode: mode.to_string(),
            seed,
            wall_time_s: wall_time.as_secs_f64(),
            exit_reason: exit_reason.to_owned(),
            restarts: Default::default(),
        }
    }
}
