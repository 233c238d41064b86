//! The scene: what the view knows of the stack, fed one sample of one topic at a time, and the
//! frame it shows. No IPC here: a live stack's subscribers or a recording's samples feed it alike.

use crate::playback::Timeline;
use mole_recorder::{Event, ProcessWatch};
use mole_types::{
    DIRECTION_PUBLISH, Fault, GRID_CONTACT, GRID_FRONTIER, Grid, LANDMARK_ANONYMOUS, Landmarks,
    MODE_ARRIVED, MODE_BOUNCE_BACK, MODE_DONE, MODE_ESCAPE, MODE_EXPLORE, MODE_GOAL, MODE_IDLE,
    MODE_STALLED, ParamChange, Particles, PlanStatus, Pose, Processes, STATUS_HAS_FRONTIER,
    STATUS_HAS_GOAL, Scan, Stats, TRUTH_IN_CONTACT, Truth, WorldMap, read_name,
};
use serde::Serialize;
use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;

/// The most particles a frame carries, evenly strided over the cloud (a filter has up to
/// 16,384): enough to see its spread, a tenth of the bytes.
pub const MAX_PARTICLES_SENT: usize = 2000;
/// How many of the newest events a frame carries.
pub const EVENTS_KEPT: usize = 20;
/// The loop latency's moving window (simulated seconds).
pub const LATENCY_WINDOW_S: f64 = 2.0;
/// True poses kept to draw a scan from the pose it was taken at.
pub const TRUTHS_KEPT: usize = 256;

/// The arena: what world/map says, sent once to each page.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Arena {
    /// Size (m); the arena spans [0, width] × [0, height].
    pub width: f64,
    pub height: f64,
    /// The true obstacles: squares `[cx, cy, side]` (m).
    pub obstacles: Vec<[f64; 3]>,
    /// The beacons `[x, y]` (m).
    pub beacons: Vec<[f64; 2]>,
    /// The robot's start `[x, y, theta]`.
    pub start: [f64; 3],
    /// The scenario's goal `[x, y, tolerance]`, if it has one.
    pub goal: Option<[f64; 3]>,
    pub robot_radius: f64,
    /// The simulated step (s).
    pub dt: f64,
}

impl Arena {
    /// The arena of a world's map.
    pub fn of(map: &WorldMap) -> Arena {
        Arena {
            width: map.arena_width,
            height: map.arena_height,
            obstacles: map
                .obstacles()
                .iter()
                .map(|o| [o.cx, o.cy, o.side])
                .collect(),
            beacons: map.beacons().iter().map(|b| [b.x, b.y]).collect(),
            start: [map.start_x, map.start_y, map.start_theta],
            goal: (map.has_goal == 1).then_some([map.goal_x, map.goal_y, map.goal_tolerance]),
            robot_radius: map.robot.radius,
            dt: map.dt,
        }
    }
}

/// A grid as a frame holds it: its geometry and all its cells.
#[derive(Debug, Clone, PartialEq)]
pub struct GridImage {
    pub tick: u64,
    pub width: usize,
    pub height: usize,
    /// Cell side (m) and the lower-left corner of cell (0, 0) (m).
    pub resolution: f64,
    pub origin_x: f64,
    pub origin_y: f64,
    /// Row-major, `width × height`.
    pub cells: Arc<[u8]>,
}

impl GridImage {
    fn of(grid: &Grid) -> GridImage {
        GridImage {
            tick: grid.header.tick,
            width: grid.width as usize,
            height: grid.height as usize,
            resolution: grid.resolution,
            origin_x: grid.origin_x,
            origin_y: grid.origin_y,
            cells: Arc::from(grid.cells()),
        }
    }

    /// Whether `other` covers the same cells (a page can update it by tiles).
    pub fn same_geometry(&self, other: &GridImage) -> bool {
        (
            self.width,
            self.height,
            self.resolution,
            self.origin_x,
            self.origin_y,
        ) == (
            other.width,
            other.height,
            other.resolution,
            other.origin_x,
            other.origin_y,
        )
    }
}

/// The robot's true pose (world/truth).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TruePose {
    pub tick: u64,
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    /// Velocities applied (m/s, rad/s).
    pub v: f64,
    pub omega: f64,
    pub in_contact: bool,
}

/// The estimate (localization/pose) and its position covariance `[σxx, σxy, σyy]` (m²).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EstimatedPose {
    pub tick: u64,
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    pub cov: [f64; 3],
}

/// A lidar scan (sensing/scan) and the true pose it was taken from, to draw it as rays.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScanRays {
    pub tick: u64,
    /// The true pose at the scan's tick (the newest one known if it is no longer kept).
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    pub angle_min: f32,
    pub angle_increment: f32,
    pub range_max: f32,
    pub ranges: Vec<f32>,
}

/// The particle cloud (localization/particles), at most [`MAX_PARTICLES_SENT`] of it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParticleCloud {
    pub tick: u64,
    /// Particles in the filter.
    pub total: usize,
    /// Every `stride`-th particle is sent.
    pub stride: usize,
    /// `[x0, y0, x1, y1, …]` (m).
    pub xy: Vec<f32>,
}

/// One landmark estimate (localization/landmarks) with its covariance `[σxx, σxy, σyy]`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LandmarkEstimate {
    /// The beacon id, `None` for an anonymous landmark.
    pub id: Option<u32>,
    pub x: f64,
    pub y: f64,
    pub cov: [f64; 3],
}

/// What the planner is doing (planning/status).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Plan {
    pub tick: u64,
    pub mode: &'static str,
    pub goal: Option<[f64; 2]>,
    pub frontier: Option<[f64; 2]>,
    /// Waypoints `[x, y]` (m).
    pub path: Vec<[f32; 2]>,
}

/// Loop latency over the moving window, from world/truth's `cmd_latency_ns` (the samples the
/// monitor's whole-run figure is made of).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Latency {
    pub p50_us: f64,
    pub p99_us: f64,
    /// Commands in the window.
    pub samples: usize,
}

/// A topic's publish rate, as its publisher last reported on stack/stats.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TopicRate {
    pub topic: String,
    pub rate_hz: f32,
}

/// A process's CPU use between its last two stack/stats reports (% of one core).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ProcessCpu {
    pub process: String,
    pub percent: f64,
}

/// Everything a frame says but the arena and the grids.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameState {
    /// Frames made so far (this one included).
    pub seq: u64,
    /// The stack's clock mode (`lockstep`, `realtime`).
    pub mode: &'static str,
    /// Whether the page may send goals and paces.
    pub controls: bool,
    /// The newest world tick and its simulated time (s).
    pub tick: u64,
    pub time_s: f64,
    /// Whether the world's last step (its end) was seen.
    pub ended: bool,
    pub truth: Option<TruePose>,
    pub pose: Option<EstimatedPose>,
    pub scan: Option<ScanRays>,
    pub particles: Option<ParticleCloud>,
    pub landmarks: Vec<LandmarkEstimate>,
    pub plan: Option<Plan>,
    pub latency: Option<Latency>,
    pub topics: Vec<TopicRate>,
    pub cpu: Vec<ProcessCpu>,
    /// The newest [`EVENTS_KEPT`] events (the recorder's JSON form) and how many there were.
    pub events: Vec<serde_json::Value>,
    pub events_total: u64,
    /// Page inputs refused so far (malformed, too long, controls off).
    pub rejected_inputs: u64,
    /// A recording's playback; absent in a live view.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub timeline: Option<Timeline>,
}

/// One frame: what the page shows at one moment. Grids are whole; each page is sent only the
/// tiles that changed since the grid it was sent last.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub arena: Arc<Arena>,
    pub state: FrameState,
    /// mapping/grid (cells 0 unexplored, 1 free, 2 occupied).
    pub frontier: Option<GridImage>,
    /// mapping/contact (cells 0 free or unknown, 1 touched).
    pub contact: Option<GridImage>,
}

/// What stack/stats last said of one process.
struct ProcessReport {
    /// When it was published (ns, wall clock).
    stamp_ns: u64,
    cpu_ns: u64,
    percent: f64,
}

/// The view's knowledge of the stack, one sample at a time.
pub struct Scene {
    mode: &'static str,
    controls: bool,
    arena: Arc<Arena>,
    truths: VecDeque<TruePose>,
    latencies: VecDeque<(u64, u64)>,
    ended: bool,
    pose: Option<EstimatedPose>,
    scan: Option<ScanRays>,
    particles: Option<ParticleCloud>,
    landmarks: Vec<LandmarkEstimate>,
    plan: Option<Plan>,
    frontier: Option<GridImage>,
    contact: Option<GridImage>,
    reports: BTreeMap<String, ProcessReport>,
    rates: BTreeMap<String, f32>,
    watch: ProcessWatch,
    events: VecDeque<serde_json::Value>,
    events_total: u64,
    seq: u64,
}

/// `[σxx, σxy, σyy]` of a row-major covariance whose rows are `n` long.
fn position_cov(cov: &[f64], n: usize) -> [f64; 3] {
    [cov[0], cov[1], cov[n + 1]]
}

/// A planner mode's name (`PlanStatus::mode`).
pub fn plan_mode_name(mode: u32) -> &'static str {
    match mode {
        MODE_IDLE => "idle",
        MODE_EXPLORE => "explore",
        MODE_BOUNCE_BACK => "bounce_back",
        MODE_GOAL => "goal",
        MODE_STALLED => "stalled",
        MODE_ESCAPE => "escape",
        MODE_DONE => "done",
        MODE_ARRIVED => "arrived",
        _ => "unknown",
    }
}

impl Scene {
    /// The scene of the stack whose world published `map`, run in clock `mode`.
    pub fn new(map: &WorldMap, mode: &'static str, controls: bool) -> Scene {
        Scene {
            mode,
            controls,
            arena: Arc::new(Arena::of(map)),
            truths: VecDeque::with_capacity(TRUTHS_KEPT),
            latencies: VecDeque::new(),
            ended: false,
            pose: None,
            scan: None,
            particles: None,
            landmarks: Vec::new(),
            plan: None,
            frontier: None,
            contact: None,
            reports: BTreeMap::new(),
            rates: BTreeMap::new(),
            watch: ProcessWatch::default(),
            events: VecDeque::new(),
            events_total: 0,
            seq: 0,
        }
    }

    /// The newest world tick seen (0 before any truth).
    pub fn tick(&self) -> u64 {
        self.truths.back().map_or(0, |t| t.tick)
    }

    /// world/map again (a restarted world): the arena it describes.
    pub fn on_map(&mut self, map: &WorldMap) {
        let arena = Arena::of(map);
        if *self.arena != arena {
            self.arena = Arc::new(arena);
        }
    }

    /// world/truth: the true pose, and the loop latency of the command it applied.
    pub fn on_truth(&mut self, truth: &Truth) {
        let tick = truth.header.tick;
        if self.truths.len() == TRUTHS_KEPT {
            self.truths.pop_front();
        }
        self.truths.push_back(TruePose {
            tick,
            x: truth.x,
            y: truth.y,
            theta: truth.theta,
            v: truth.v,
            omega: truth.omega,
            in_contact: truth.flags & TRUTH_IN_CONTACT != 0,
        });
        if truth.cmd_latency_ns > 0 {
            self.latencies.push_back((tick, truth.cmd_latency_ns));
        }
        let window = (LATENCY_WINDOW_S / self.arena.dt).round() as u64;
        while self
            .latencies
            .front()
            .is_some_and(|(t, _)| t.saturating_add(window) < tick)
        {
            self.latencies.pop_front();
        }
        self.ended |= truth.is_end();
    }

    /// localization/pose.
    pub fn on_pose(&mut self, pose: &Pose) {
        self.pose = Some(EstimatedPose {
            tick: pose.header.tick,
            x: pose.x,
            y: pose.y,
            theta: pose.theta,
            cov: position_cov(&pose.covariance, 3),
        });
    }

    /// sensing/scan.
    pub fn on_scan(&mut self, scan: &Scan) {
        let tick = scan.header.tick;
        let from = self
            .truths
            .iter()
            .rev()
            .find(|t| t.tick == tick)
            .or(self.truths.back());
        let (x, y, theta) = from.map_or((0.0, 0.0, 0.0), |t| (t.x, t.y, t.theta));
        self.scan = Some(ScanRays {
            tick,
            x,
            y,
            theta,
            angle_min: scan.angle_min,
            angle_increment: scan.angle_increment,
            range_max: scan.range_max,
            ranges: scan.ranges().to_vec(),
        });
    }

    /// localization/particles: every stride-th particle, at most [`MAX_PARTICLES_SENT`].
    pub fn on_particles(&mut self, particles: &Particles) {
        let all = particles.particles();
        let stride = all.len().div_ceil(MAX_PARTICLES_SENT).max(1);
        self.particles = Some(ParticleCloud {
            tick: particles.header.tick,
            total: all.len(),
            stride,
            xy: all
                .iter()
                .step_by(stride)
                .flat_map(|p| [p.x, p.y])
                .collect(),
        });
    }

    /// localization/landmarks.
    pub fn on_landmarks(&mut self, landmarks: &Landmarks) {
        self.landmarks = landmarks
            .landmarks()
            .iter()
            .map(|l| LandmarkEstimate {
                id: (l.id != LANDMARK_ANONYMOUS).then_some(l.id),
                x: l.x,
                y: l.y,
                cov: position_cov(&l.covariance, 2),
            })
            .collect();
    }

    /// planning/status.
    pub fn on_plan(&mut self, status: &PlanStatus) {
        self.plan = Some(Plan {
            tick: status.header.tick,
            mode: plan_mode_name(status.mode),
            goal: (status.flags & STATUS_HAS_GOAL != 0).then_some([status.goal_x, status.goal_y]),
            frontier: (status.flags & STATUS_HAS_FRONTIER != 0)
                .then_some([status.frontier_x, status.frontier_y]),
            path: status.path().to_vec(),
        });
    }

    /// mapping/grid or mapping/contact (told apart by the grid's kind).
    pub fn on_grid(&mut self, grid: &Grid) {
        let slot = match grid.kind {
            GRID_FRONTIER => &mut self.frontier,
            GRID_CONTACT => &mut self.contact,
            _ => return,
        };
        if slot.as_ref().is_none_or(|g| g.tick != grid.header.tick) {
            *slot = Some(GridImage::of(grid));
        }
    }

    /// stack/stats: the process's CPU since its previous report, its topics' publish rates.
    pub fn on_stats(&mut self, stats: &Stats) {
        let process = read_name(&stats.process).into_owned();
        let stamp_ns = stats.header.stamp_ns;
        let percent = match self.reports.get(&process) {
            Some(last) if stamp_ns > last.stamp_ns && stats.cpu_ns >= last.cpu_ns => {
                100.0 * (stats.cpu_ns - last.cpu_ns) as f64 / (stamp_ns - last.stamp_ns) as f64
            }
            // The first report, or a restarted process (its CPU time starts again).
            _ => 0.0,
        };
        self.reports.insert(
            process,
            ProcessReport {
                stamp_ns,
                cpu_ns: stats.cpu_ns,
                percent,
            },
        );
        for t in stats.topics() {
            if t.direction == DIRECTION_PUBLISH {
                self.rates
                    .insert(read_name(&t.topic).into_owned(), t.rate_hz);
            }
        }
    }

    /// stack/processes: starts, restarts, swaps, exits (the recorder's [`ProcessWatch`]), at
    /// the newest world tick.
    pub fn on_processes(&mut self, report: &Processes) {
        self.on_processes_at(report, self.tick());
    }

    /// stack/processes read at world tick `tick` (a recording's: the newest the recorder had
    /// read).
    pub fn on_processes_at(&mut self, report: &Processes, tick: u64) {
        for event in self.watch.update(report) {
            self.event(&event, tick);
        }
    }

    /// stack/faults: a fault `mole fault` injected, at the newest world tick.
    pub fn on_fault(&mut self, fault: &Fault) {
        self.on_fault_at(fault, self.tick());
    }

    /// stack/faults read at world tick `tick` (a recording's).
    pub fn on_fault_at(&mut self, fault: &Fault, tick: u64) {
        self.event(&Event::of_fault(fault), tick);
    }

    /// stack/params: a setting a process took or refused (`mole param set`), at the newest
    /// world tick (a request is no event).
    pub fn on_param(&mut self, change: &ParamChange) {
        self.on_param_at(change, self.tick());
    }

    /// stack/params read at world tick `tick` (a recording's).
    pub fn on_param_at(&mut self, change: &ParamChange, tick: u64) {
        if let Some(event) = Event::of_param(change) {
            self.event(&event, tick);
        }
    }

    fn event(&mut self, event: &Event, tick: u64) {
        let json = serde_json::from_str(&event.to_json(tick)).unwrap_or(serde_json::Value::Null);
        if self.events.len() == EVENTS_KEPT {
            self.events.pop_front();
        }
        self.events.push_back(json);
        self.events_total += 1;
    }

    /// Loop latency over the window, `None` before any command reached the world.
    fn latency(&self) -> Option<Latency> {
        let mut us: Vec<f64> = self
            .latencies
            .iter()
            .map(|(_, ns)| *ns as f64 / 1e3)
            .collect();
        if us.is_empty() {
            return None;
        }
        us.sort_by(f64::total_cmp);
        let at = |q: f64| us[((us.len() - 1) as f64 * q).round() as usize];
        Some(Latency {
            p50_us: at(0.5),
            p99_us: at(0.99),
            samples: us.len(),
        })
    }

    /// The frame of what is known now.
    pub fn frame(&mut self, rejected_inputs: u64) -> Frame {
        self.seq += 1;
        let truth = self.truths.back().copied();
        let tick = truth.map_or(0, |t| t.tick);
        Frame {
            arena: self.arena.clone(),
            state: FrameState {
                seq: self.seq,
                mode: self.mode,
                controls: self.controls,
                tick,
                time_s: tick as f64 * self.arena.dt,
                ended: self.ended,
                truth,
                pose: self.pose,
                scan: self.scan.clone(),
                particles: self.particles.clone(),
                landmarks: self.landmarks.clone(),
                plan: self.plan.clone(),
                latency: self.latency(),
                topics: self
                    .rates
                    .iter()
                    .map(|(topic, rate_hz)| TopicRate {
                        topic: topic.clone(),
                        rate_hz: *rate_hz,
                    })
                    .collect(),
                cpu: self
                    .reports
                    .iter()
                    .map(|(process, r)| ProcessCpu {
                        process: process.clone(),
                        percent: r.percent,
                    })
                    .collect(),
                events: self.events.iter().cloned().collect(),
                events_total: self.events_total,
                rejected_inputs,
                timeline: None,
            },
            frontier: self.frontier.clone(),
            contact: self.contact.clone(),
        }
    }
}
