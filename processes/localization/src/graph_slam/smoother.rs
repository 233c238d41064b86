//! GraphSLAM in the process (algorithms §6.9.4): an EKF-SLAM front-end publishes the pose every
//! step, and a smoother thread that owns the pose graph solves it in the background.
//!
//! What flows where:
//! - The pose (`localization/pose`) is the front-end's, every step. The step never waits for
//!   the smoother, and the pose that mapping and planning use stays a function of the readings
//!   alone, not of thread timing (the lockstep runs stay reproducible).
//! - Each step's odometry, the beacon readings the front-end accepted and the position fix go
//!   to the smoother through a bounded queue that never blocks the step. A reading reaches the
//!   graph keyed by the front-end's landmark slot, so readings without beacon ids arrive
//!   already associated.
//! - The smoother adds one pose per step (up to [`SMOOTHER_POSES`]) and, after every
//!   [`SOLVE_EVERY`] steps or a tenth of the graph's poses, whichever is more, runs
//!   [`SOLVE_ITERATIONS`] Levenberg–Marquardt iterations from the previous optimum, computes the
//!   landmarks' marginal covariances and posts the result. Which steps it solves after depends
//!   on the step count only, so the same readings give the same solutions.
//! - The landmarks (`localization/landmarks`) are republished every step: for each landmark of
//!   the front-end's map, the smoother's mean and marginal covariance from its newest finished
//!   solve when that solve has it, else the front-end's.
//! - The smoothed trajectory (`localization/trajectory`) is published after each finished solve
//!   that the step took over: every pose of the graph but its anchor, each with the tick of the
//!   step whose odometry reached it ([`Estimator::write_trajectory`]). Its newest pose is also
//!   [`GraphSlamEstimator::smoothed_pose`].
//! - When the queue overflows (the smoother fell [`QUEUE_STEPS`] steps behind) or the graph is
//!   full, the smoother stops for the rest of the run (logged once), and the landmarks are the
//!   front-end's from then on.
//!
//! The step path allocates nothing. The smoother's graph and solver workspace are reserved up
//! front; its symbolic factorisation (faer) is redone, with allocation, on the smoother thread
//! after the graph grew. The trajectory travels in three buffers reserved for the whole graph:
//! the smoother fills its own, swaps it with the posted one under the lock, and the step swaps
//! the posted one with the estimator's, so neither side copies under the lock.

use super::{GraphCapacity, GraphSlamConfig, PoseGraph};
use crate::slam::{Association, EkfSlamEstimator, SLAM_CAPACITY, write_landmarks};
use crate::{Estimator, LocalizationError, Readings};
use mole_types::{
    BeaconReading, EstimatorKind, Landmarks, MAX_BEACONS, MAX_TRAJECTORY_POSES, Odom, Pose, Pose2,
    Trajectory, TrajectoryPose, WorldMap,
};
use nalgebra::{Matrix2, Vector2, Vector3};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

/// Poses the smoother's graph holds: 200 s at 100 Hz. One GraphSLAM solve of a graph this size
/// takes a few hundred ms on the smoother thread.
pub const SMOOTHER_POSES: usize = 20_000;
/// Readings per pose reserved up front (the graph grows past it on the smoother thread).
const READINGS_PER_POSE: usize = 4;
/// The smoother solves after at least this many new steps (1 s at 100 Hz).
pub const SOLVE_EVERY: usize = 100;
/// Levenberg–Marquardt iterations per solve; the next solve goes on from its result.
pub const SOLVE_ITERATIONS: usize = 10;
/// Steps the queue to the smoother holds.
pub const QUEUE_STEPS: usize = 1024;

// Every pose of the graph but its anchor fits in one `localization/trajectory` message.
const _: () = assert!(SMOOTHER_POSES - 1 <= MAX_TRAJECTORY_POSES);

/// A smoothed pose (x, y, θ) with the tick of the step whose odometry reached it.
type StampedPose = (u64, Vector3<f64>);

/// One step as the smoother needs it.
#[derive(Debug, Clone, Copy)]
struct StepRecord {
    /// The step's control; `None` for readings taken without a move since the last step.
    odom: Option<Odom>,
    /// Its slide along a wall ([`crate::contact`]), robot frame at the arc's end.
    slide: Vector2<f64>,
    n_readings: usize,
    /// The accepted readings, `id` = the front-end's landmark slot.
    readings: [BeaconReading; MAX_BEACONS],
    /// A usable position fix (x, y, σ).
    fix: Option<(f64, f64, f64)>,
}

/// Work for the smoother thread.
#[derive(Debug)]
#[allow(
    clippy::large_enum_variant,
    reason = "a step travels by value in the queue's preallocated slots: boxing it would \
              allocate on every step"
)]
enum Job {
    /// Add a step to the graph (and solve when one is due).
    Step(StepRecord),
    /// Solve what has arrived, post it and acknowledge.
    Settle,
}

/// The newest solution, posted by the smoother.
#[derive(Debug)]
struct Posted {
    /// Solves posted so far.
    solves: u64,
    /// Steps in the graph at that solve.
    steps: u64,
    /// The newest smoothed pose.
    pose: Vector3<f64>,
    /// Per landmark of the graph: (front-end slot, mean, marginal covariance).
    landmarks: Vec<(usize, Vector2<f64>, Matrix2<f64>)>,
    /// The smoothed trajectory, the anchor left out (swapped in and out, never copied).
    trajectory: Vec<StampedPose>,
    /// The degrees of freedom of the smoothed map's mean landmark NEES.
    nees_dof: f64,
    /// The graph is full: no more solutions.
    stopped: bool,
}

/// GraphSLAM: an EKF-SLAM front-end and a pose-graph smoother on its own thread (see the module
/// documentation for what is published).
pub struct GraphSlamEstimator {
    front: EkfSlamEstimator,
    queue: Option<SyncSender<Job>>,
    settled: Receiver<()>,
    posted: Arc<Mutex<Posted>>,
    smoother: Option<JoinHandle<()>>,
    /// The step being recorded, sent when the next one starts.
    record: StepRecord,
    pending: bool,
    /// The newest solution's landmarks by front-end slot.
    smoothed: Vec<Option<(Vector2<f64>, Matrix2<f64>)>>,
    /// The smoothed map's mean-NEES degrees of freedom, with `smoothed`.
    smoothed_dof: f64,
    smoothed_pose: Option<(u64, Pose2)>,
    /// The newest solution's trajectory.
    trajectory: Vec<StampedPose>,
    solves: u64,
    live: bool,
}

impl GraphSlamEstimator {
    /// GraphSLAM for the world in `map`: the front-end as [`EkfSlamEstimator::from_map`], the
    /// graph anchored at the start pose, the smoother thread started.
    pub fn from_map(map: &WorldMap) -> Result<Self, LocalizationError> {
        Self::with_settings(map, &crate::Settings::default())
    }

    /// [`GraphSlamEstimator::from_map`] with the front-end's `settings.slam` and the solver's
    /// `settings.graph_slam`.
    pub fn with_settings(
        map: &WorldMap,
        settings: &crate::Settings,
    ) -> Result<Self, LocalizationError> {
        Self::with_front(
            EkfSlamEstimator::with_settings(map, settings),
            map,
            settings,
            None,
        )
    }

    /// GraphSLAM going on from another estimator's output (see [`crate::resume`]): the front-end
    /// resumed from `pose` and `landmarks`, a new graph anchored at the pose with the pose's σ
    /// (the earlier trajectory is not taken over). A landmark enters the graph when it is seen
    /// again; until then the front-end's estimate of it is published.
    pub fn resume(
        map: &WorldMap,
        pose: &Pose,
        landmarks: Option<&Landmarks>,
    ) -> Result<Self, LocalizationError> {
        Self::resume_with(map, &crate::Settings::default(), pose, landmarks)
    }

    /// [`GraphSlamEstimator::resume`] with these settings.
    pub fn resume_with(
        map: &WorldMap,
        settings: &crate::Settings,
        pose: &Pose,
        landmarks: Option<&Landmarks>,
    ) -> Result<Self, LocalizationError> {
        let front = EkfSlamEstimator::resume_with(map, settings, pose, landmarks);
        let diagonal = [pose.covariance[0], pose.covariance[4], pose.covariance[8]];
        Self::with_front(front, map, settings, Some(diagonal))
    }

    /// The estimator around `front`, its graph anchored at the front-end's pose with the
    /// default prior σ, widened to √`variances` where those are larger.
    fn with_front(
        front: EkfSlamEstimator,
        map: &WorldMap,
        settings: &crate::Settings,
        variances: Option<[f64; 3]>,
    ) -> Result<Self, LocalizationError> {
        let mut config = GraphSlamConfig::from_map(map);
        config.solver = settings.graph_slam;
        if let Some(variances) = variances {
            for (std, var) in config.prior_std.iter_mut().zip(variances) {
                if var.is_finite() && var.sqrt() > *std {
                    *std = var.sqrt();
                }
            }
        }
        let graph = PoseGraph::new(
            front.pose(),
            config,
            GraphCapacity {
                poses: SMOOTHER_POSES,
                landmarks: SLAM_CAPACITY,
                observations: READINGS_PER_POSE * SMOOTHER_POSES,
            },
        );
        let (queue, jobs) = sync_channel(QUEUE_STEPS);
        let (acknowledge, settled) = sync_channel(1);
        let posted = Arc::new(Mutex::new(Posted {
            solves: 0,
            steps: 0,
            pose: Vector3::zeros(),
            landmarks: Vec::with_capacity(SLAM_CAPACITY),
            trajectory: Vec::with_capacity(SMOOTHER_POSES),
            nees_dof: 0.0,
            stopped: false,
        }));
        let shared = Arc::clone(&posted);
        let smoother = std::thread::Builder::new()
            .name("graph-slam-smoother".into())
            .spawn(move || smooth(graph, &jobs, &shared, &acknowledge))
            .map_err(|e| LocalizationError::Smoother(e.to_string()))?;
        Ok(Self {
            front,
            queue: Some(queue),
            settled,
            posted,
            smoother: Some(smoother),
            record: StepRecord {
                odom: None,
                slide: Vector2::zeros(),
                n_readings: 0,
                readings: [BeaconReading::default(); MAX_BEACONS],
                fix: None,
            },
            pending: false,
            smoothed: vec![None; SLAM_CAPACITY],
            smoothed_dof: 0.0,
            smoothed_pose: None,
            trajectory: Vec::with_capacity(SMOOTHER_POSES),
            solves: 0,
            live: true,
        })
    }

    /// The front-end filter.
    pub fn front_end(&self) -> &EkfSlamEstimator {
        &self.front
    }

    /// Solutions taken over from the smoother so far.
    pub fn solves(&self) -> u64 {
        self.solves
    }

    /// The newest smoothed pose taken over, with the number of steps it comes after.
    pub fn smoothed_pose(&self) -> Option<(u64, Pose2)> {
        self.smoothed_pose
    }

    /// Waits until the smoother has every step recorded so far in its graph, has solved it and
    /// posted the solution, and takes that solution over. Not for the step path: this waits
    /// for a solve. Tests and the end of a run use it.
    pub fn settle(&mut self) {
        self.send_pending();
        if let Some(queue) = &self.queue
            && queue.send(Job::Settle).is_ok()
            && self.settled.recv().is_ok()
        {
            self.take_solution(true);
        }
    }

    /// Sends the recorded step, if any; a full queue or a dead smoother stops smoothing.
    fn send_pending(&mut self) {
        if !self.pending {
            return;
        }
        self.pending = false;
        let Some(queue) = &self.queue else {
            return;
        };
        match queue.try_send(Job::Step(self.record)) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => {
                tracing::warn!(
                    "GraphSLAM smoother {QUEUE_STEPS} steps behind: smoothing stops, the \
                     front-end's landmarks are published from now on"
                );
                self.stop();
            }
            Err(TrySendError::Disconnected(_)) => {
                tracing::warn!("GraphSLAM smoother thread ended: smoothing stops");
                self.stop();
            }
        }
    }

    /// Stops smoothing for the rest of the run.
    fn stop(&mut self) {
        self.queue = None;
        self.live = false;
    }

    /// Takes the newest posted solution over; `wait` blocks on the lock (settling), otherwise a
    /// busy lock means next step.
    fn take_solution(&mut self, wait: bool) {
        let guard = if wait {
            self.posted.lock().ok()
        } else {
            self.posted.try_lock().ok()
        };
        let Some(mut posted) = guard else {
            return;
        };
        if posted.stopped && self.live {
            tracing::warn!("GraphSLAM graph full ({SMOOTHER_POSES} poses): smoothing stops");
            self.queue = None;
            self.live = false;
        }
        if posted.solves == self.solves {
            return;
        }
        self.solves = posted.solves;
        self.smoothed_pose = Some((
            posted.steps,
            Pose2::new(posted.pose[0], posted.pose[1], posted.pose[2]),
        ));
        self.smoothed.fill(None);
        self.smoothed_dof = posted.nees_dof;
        for &(slot, mean, cov) in &posted.landmarks {
            if let Some(entry) = self.smoothed.get_mut(slot) {
                *entry = Some((mean, cov));
            }
        }
        std::mem::swap(&mut self.trajectory, &mut posted.trajectory);
    }
}

impl Drop for GraphSlamEstimator {
    /// Closes the queue, which ends the smoother thread, and joins it.
    fn drop(&mut self) {
        self.queue = None;
        if let Some(smoother) = self.smoother.take() {
            let _ = smoother.join();
        }
    }
}

impl Estimator for GraphSlamEstimator {
    fn id(&self) -> u32 {
        EstimatorKind::GraphSlam.code()
    }

    /// The front-end's prediction; the step before goes to the smoother and this one starts.
    fn predict(&mut self, odom: &Odom) {
        self.predict_sliding(odom, &Vector2::zeros());
    }

    /// The front-end's prediction with the slide, which the step's odometry factor carries too.
    fn predict_sliding(&mut self, odom: &Odom, sideways: &Vector2<f64>) {
        self.front.predict_sliding(odom, sideways);
        self.send_pending();
        self.record.odom = Some(*odom);
        self.record.slide = *sideways;
        self.record.n_readings = 0;
        self.record.fix = None;
        self.pending = true;
    }

    /// The front-end's correction; the readings it associated and the fix join the step's
    /// record, and the smoother's newest solution is taken over if the smoother is not posting
    /// just now.
    fn correct(&mut self, readings: &Readings<'_>) {
        self.front.correct(readings);
        if !self.pending {
            self.record.odom = None;
            self.record.n_readings = 0;
            self.record.fix = None;
            self.pending = true;
        }
        if let Some(fix) = readings.fix.filter(|f| f.valid == 1) {
            self.record.fix = Some((fix.x, fix.y, fix.std));
        }
        if let Some(beacons) = readings.beacons {
            for (reading, decision) in beacons.readings().iter().zip(self.front.decisions()) {
                let slot = match decision {
                    Ok(Association::Matched { slot, .. } | Association::New { slot, .. }) => *slot,
                    _ => continue,
                };
                if self.record.n_readings < MAX_BEACONS {
                    self.record.readings[self.record.n_readings] = BeaconReading {
                        id: slot as u32,
                        ..*reading
                    };
                    self.record.n_readings += 1;
                }
            }
        }
        self.take_solution(false);
    }

    fn pose(&self) -> Pose2 {
        self.front.pose()
    }

    fn covariance(&self) -> [f64; 9] {
        self.front.covariance()
    }

    fn rejected(&self) -> u64 {
        self.front.rejected()
    }

    fn ignored(&self) -> u64 {
        self.front.ignored()
    }

    /// The front-end's landmarks, each replaced by its smoothed estimate when the smoother is
    /// live and its newest solution has it.
    fn write_landmarks(&self, out: &mut Landmarks) -> bool {
        let live = self.live;
        let landmarks = self
            .front
            .filter()
            .landmarks()
            .enumerate()
            .map(|(slot, mut l)| {
                if live && let Some(Some((mean, cov))) = self.smoothed.get(slot) {
                    l.mean = *mean;
                    l.cov = *cov;
                }
                l
            });
        // The smoother's degrees of freedom when its solution holds every landmark written,
        // else the front-end's (a landmark seen since the last solve is the filter's alone).
        let n = self.front.filter().len();
        let all_smoothed = live && self.smoothed.iter().take(n).all(Option::is_some);
        let dof = if all_smoothed {
            self.smoothed_dof
        } else {
            self.front.filter().mean_nees_dof()
        };
        write_landmarks(EstimatorKind::GraphSlam, landmarks, dof, out)
    }

    fn smoother_solves(&self) -> u64 {
        self.solves
    }

    /// The newest solution's trajectory, ticks counted from its first pose's; a pose whose tick
    /// does not come after the one before (a restarted world) or lies 2³² steps on is left out.
    fn write_trajectory(&self, out: &mut Trajectory) -> bool {
        let first_tick = self.trajectory.first().map_or(0, |&(tick, _)| tick);
        let mut n = 0;
        let mut previous = None;
        for &(tick, pose) in &self.trajectory {
            let offset = tick
                .checked_sub(first_tick)
                .and_then(|d| u32::try_from(d).ok());
            let Some(offset) = offset.filter(|o| previous.is_none_or(|p| *o > p)) else {
                continue;
            };
            let Some(slot) = out.poses.get_mut(n) else {
                break;
            };
            *slot = TrajectoryPose {
                tick_offset: offset,
                x: pose[0] as f32,
                y: pose[1] as f32,
                theta: pose[2] as f32,
            };
            previous = Some(offset);
            n += 1;
        }
        out.first_tick = first_tick;
        out.n_poses = n as u32;
        out.estimator = EstimatorKind::GraphSlam.code();
        true
    }
}

/// The smoother thread: adds each step to the graph, solves when due and posts the solution;
/// ends when the queue closes.
fn smooth(
    mut graph: PoseGraph,
    jobs: &Receiver<Job>,
    posted: &Mutex<Posted>,
    acknowledge: &SyncSender<()>,
) {
    let mut covariances = Vec::with_capacity(SLAM_CAPACITY);
    // The tick of every pose but the anchor, and the trajectory being prepared for the post.
    let mut ticks = Vec::with_capacity(SMOOTHER_POSES);
    let mut trajectory = Vec::with_capacity(SMOOTHER_POSES);
    let mut since_solve = 0;
    let mut stopped = false;
    while let Ok(job) = jobs.recv() {
        match job {
            Job::Step(_) if stopped => {}
            Job::Step(record) => {
                if graph.poses().len() >= SMOOTHER_POSES {
                    stopped = true;
                    if let Ok(mut p) = posted.lock() {
                        p.stopped = true;
                    }
                    continue;
                }
                add_step(&mut graph, &record, &mut ticks);
                since_solve += 1;
                if since_solve >= SOLVE_EVERY.max(graph.poses().len() / 10) {
                    solve_and_post(
                        &mut graph,
                        &ticks,
                        &mut covariances,
                        &mut trajectory,
                        posted,
                    );
                    since_solve = 0;
                }
            }
            Job::Settle => {
                if since_solve > 0 && !stopped {
                    solve_and_post(
                        &mut graph,
                        &ticks,
                        &mut covariances,
                        &mut trajectory,
                        posted,
                    );
                    since_solve = 0;
                }
                let _ = acknowledge.send(());
            }
        }
    }
}

/// A new pose reached by the step's odometry, its tick kept in `ticks` (a refused control keeps
/// the newest pose), and the step's readings from it. Refusals are counted by the graph.
fn add_step(graph: &mut PoseGraph, record: &StepRecord, ticks: &mut Vec<u64>) {
    let newest = graph.poses().len() - 1;
    let added = record.odom.and_then(|odom| {
        let at = graph.add_sliding_pose(&odom, &record.slide).ok()?;
        ticks.push(odom.header.tick);
        Some(at)
    });
    let at = added.unwrap_or(newest);
    for reading in &record.readings[..record.n_readings] {
        let _ = graph.add_observation(at, reading);
    }
    if let Some((x, y, std)) = record.fix {
        let _ = graph.add_position(at, x, y, std);
    }
}

/// One solve from the current estimate, the landmark marginals, and the post; the trajectory
/// is prepared in `trajectory` (pose i + 1 of the graph at `ticks[i]`) and swapped with the
/// posted one.
fn solve_and_post(
    graph: &mut PoseGraph,
    ticks: &[u64],
    covariances: &mut Vec<Matrix2<f64>>,
    trajectory: &mut Vec<StampedPose>,
    posted: &Mutex<Posted>,
) {
    if graph.optimize(SOLVE_ITERATIONS).is_err() || graph.landmark_covariances(covariances).is_err()
    {
        return;
    }
    trajectory.clear();
    trajectory.extend(
        ticks
            .iter()
            .copied()
            .zip(graph.poses()[1..].iter().copied()),
    );
    let Ok(mut p) = posted.lock() else {
        return;
    };
    std::mem::swap(&mut p.trajectory, trajectory);
    p.solves += 1;
    p.steps = (graph.poses().len() - 1) as u64;
    p.pose = graph.poses()[graph.poses().len() - 1];
    p.nees_dof = graph.landmark_nees_dof();
    p.landmarks.clear();
    for ((&slot, &mean), &cov) in graph
        .landmark_ids()
        .iter()
        .zip(graph.landmarks())
        .zip(covariances.iter())
    {
        p.landmarks.push((slot as usize, mean, cov));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::zeroed_map;
    use mole_types::Message;

    /// The published trajectory holds every pose the odometry reached, each at its step's tick
    /// (a skipped step included), and ends at the smoothed pose taken over.
    #[test]
    fn the_trajectory_carries_every_step_at_its_tick() {
        let mut map = zeroed_map();
        (map.start_x, map.start_y, map.dt) = (1.0, 1.0, 0.01);
        (map.sensors.odom_v_std, map.sensors.odom_omega_std) = (0.05, 0.05);
        let mut graph = GraphSlamEstimator::from_map(&map).expect("smoother starts");
        let mut odom: Odom = bytemuck::Zeroable::zeroed();
        (odom.v, odom.omega, odom.dt) = (0.5, 0.2, 0.01);
        // Steps 40..=290, step 100 missed (a realtime step the process did not handle).
        let ticks: Vec<u64> = (40..=290).filter(|&t| t != 100).collect();
        for &tick in &ticks {
            odom.header.tick = tick;
            graph.step(&Readings::of(&odom));
        }
        graph.settle();
        assert!(graph.smoother_solves() > 0);
        let mut out: Box<Trajectory> = bytemuck::zeroed_box();
        assert!(graph.write_trajectory(&mut out));
        assert_eq!(out.validate(), Ok(()));
        assert_eq!(out.estimator, EstimatorKind::GraphSlam.code());
        assert_eq!(out.first_tick, 40);
        let published: Vec<u64> = out
            .poses()
            .iter()
            .map(|p| out.first_tick + u64::from(p.tick_offset))
            .collect();
        assert_eq!(published, ticks);
        let (steps, newest) = graph.smoothed_pose().expect("a solution taken over");
        assert_eq!(steps as usize, ticks.len());
        let last = out.poses()[ticks.len() - 1];
        assert_eq!((last.x, last.y), (newest.x as f32, newest.y as f32));
    }
}
