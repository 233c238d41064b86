//! The view's side of IPC: a subscriber on every topic it shows, drained into the scene.
//!
//! In lockstep a full queue makes its publisher wait, so every queue is read each step: the
//! world's truth (published once a step) wakes the view, as it wakes the recorder. In realtime
//! nothing wakes it: it drains every [`crate::FRAME_PERIOD`], and a queue that filled meanwhile
//! drops its oldest samples (the view shows the newest). The truth, the statistics and the
//! process table are handed to the scene sample by sample (latency window, CPU deltas, events);
//! of the others only the newest sample, once per drain.

use crate::Scene;
use mole_runtime::{ClockMode, Context, RuntimeError, Subscriber, Waker};
use mole_types::{
    Fault, Grid, Landmarks, Message, ParamChange, Particles, PlanStatus, Pose, Processes, Scan,
    Stats, Truth, WorldMap, topics,
};

/// Every topic the view shows.
pub struct Taps {
    /// The world's map: its first sample starts the scene.
    pub map: Subscriber<WorldMap>,
    truth: Subscriber<Truth>,
    pose: Subscriber<Pose>,
    scan: Subscriber<Scan>,
    particles: Subscriber<Particles>,
    landmarks: Subscriber<Landmarks>,
    plan: Subscriber<PlanStatus>,
    grid: Subscriber<Grid>,
    contact: Subscriber<Grid>,
    stats: Subscriber<Stats>,
    processes: Subscriber<Processes>,
    faults: Subscriber<Fault>,
    params: Subscriber<ParamChange>,
}

/// Drains `subscriber`; the newest sample, if a new one came, goes to `on_newest`.
fn newest<M: Message>(subscriber: &mut Subscriber<M>, on_newest: impl FnOnce(&M)) {
    if subscriber.drain(|_| {}) > 0
        && let Some(message) = subscriber.latest()
    {
        on_newest(message);
    }
}

impl Taps {
    /// Subscribes passively to every shown topic, but for the map (rare; it starts the scene)
    /// and, in lockstep, the truth, which wake the view.
    pub fn open(ctx: &Context) -> Result<Taps, RuntimeError> {
        let truth = match ctx.mode() {
            ClockMode::Lockstep => ctx.subscriber(topics::WORLD_TRUTH)?,
            ClockMode::Realtime => ctx.passive_subscriber(topics::WORLD_TRUTH)?,
        };
        Ok(Taps {
            map: ctx.subscriber(topics::WORLD_MAP)?,
            truth,
            pose: ctx.passive_subscriber(topics::LOCALIZATION_POSE)?,
            scan: ctx.passive_subscriber(topics::SENSING_SCAN)?,
            particles: ctx.passive_subscriber(topics::LOCALIZATION_PARTICLES)?,
            landmarks: ctx.passive_subscriber(topics::LOCALIZATION_LANDMARKS)?,
            plan: ctx.passive_subscriber(topics::PLANNING_STATUS)?,
            grid: ctx.passive_subscriber(topics::MAPPING_GRID)?,
            contact: ctx.passive_subscriber(topics::MAPPING_CONTACT)?,
            stats: ctx.passive_subscriber(topics::STACK_STATS)?,
            processes: ctx.passive_subscriber(topics::STACK_PROCESSES)?,
            faults: ctx.passive_subscriber(topics::STACK_FAULTS)?,
            params: ctx.passive_subscriber(topics::STACK_PARAMS)?,
        })
    }

    /// The wakers of the topics that wake the view.
    pub fn wakers(&self, mode: ClockMode) -> Vec<Waker> {
        let mut wakers = vec![self.map.waker()];
        if mode == ClockMode::Lockstep {
            wakers.push(self.truth.waker());
        }
        wakers
    }

    /// Reads every queue; the samples go to `scene` (the first map starts it).
    pub fn drain(&mut self, scene: &mut Option<Scene>, mode: &'static str, controls: bool) {
        let Some(scene) = scene else {
            newest(&mut self.map, |m| {
                *scene = Some(Scene::new(m, mode, controls))
            });
            // No scene yet: the queues are read all the same, so no lockstep publisher waits.
            self.discard();
            return;
        };
        newest(&mut self.map, |m| scene.on_map(m));
        // Truth first: the scan is drawn from the true pose of its tick.
        self.truth.drain(|t| scene.on_truth(t));
        newest(&mut self.pose, |p| scene.on_pose(p));
        newest(&mut self.scan, |s| scene.on_scan(s));
        newest(&mut self.particles, |p| scene.on_particles(p));
        newest(&mut self.landmarks, |l| scene.on_landmarks(l));
        newest(&mut self.plan, |p| scene.on_plan(p));
        newest(&mut self.grid, |g| scene.on_grid(g));
        newest(&mut self.contact, |g| scene.on_grid(g));
        self.stats.drain(|s| scene.on_stats(s));
        self.processes.drain(|p| scene.on_processes(p));
        self.faults.drain(|f| scene.on_fault(f));
        self.params.drain(|p| scene.on_param(p));
    }

    /// Reads every queue but the map's and forgets the samples.
    fn discard(&mut self) {
        self.truth.drain(|_| {});
        self.pose.drain(|_| {});
        self.scan.drain(|_| {});
        self.particles.drain(|_| {});
        self.landmarks.drain(|_| {});
        self.plan.drain(|_| {});
        self.grid.drain(|_| {});
        self.contact.drain(|_| {});
        self.stats.drain(|_| {});
        self.processes.drain(|_| {});
        self.faults.drain(|_| {});
        self.params.drain(|_| {});
    }
}
