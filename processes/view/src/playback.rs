//! A recording in the view: the samples of every shown topic indexed per topic by tick (a seek
//! is a binary search), a playback clock (play, pause, seek, speed, paced by the recording's
//! simulated time) and the scene fed up to the clock's tick. No IPC here: a recording's view
//! opens no iceoryx2 node and needs no stack.
//!
//! Played forward, each frame feeds the scene what a live view would have read since the last
//! one: every truth, statistics report and process table, and the newest sample of each other
//! topic. A seek backwards, or more than [`Reel::history`] ticks forwards, rebuilds the scene
//! afresh: the truths of the moving windows before the tick (the loop latency's, the poses a
//! scan is drawn from), every statistics report and process table up to it (the CPU deltas, the
//! rates, the events), and the newest sample at or before it of every other topic.

use crate::input::{MAX_SPEED, MIN_SPEED, TimelineOp};
use crate::scene::{Frame, LATENCY_WINDOW_S, Scene, TRUTHS_KEPT};
use mole_recorder::tape::{Sample, TapeError, Window, for_each_sample, read_tape};
use mole_types::{
    ClockMode, Fault, Grid, Landmarks, Message, ParamChange, Particles, PlanStatus, Pose,
    Processes, Scan, Stats, Truth, WorldMap, topics,
};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The timeline as a frame carries it (a recording's view only).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Timeline {
    /// The recording's first and last world tick.
    pub first_tick: u64,
    pub last_tick: u64,
    /// The tick shown.
    pub tick: u64,
    pub playing: bool,
    /// × the recorded simulated time.
    pub speed: f64,
}

/// The playback clock: a tick within the recording's, moved by the wall clock while playing,
/// `speed` times as fast as the recorded simulated time (its log time).
#[derive(Debug, Clone, PartialEq)]
pub struct Clock {
    first: u64,
    last: u64,
    /// Where it is, in ticks (fractional: a slow speed moves less than a tick a frame).
    at: f64,
    playing: bool,
    speed: f64,
    /// The simulated step (s).
    step_s: f64,
}

impl Clock {
    /// A clock over `first..=last`, steps of `period_ns`, paused at the first tick, at 1×.
    pub fn new(first: u64, last: u64, period_ns: u64) -> Clock {
        Clock {
            first,
            last: last.max(first),
            at: first as f64,
            playing: false,
            speed: 1.0,
            step_s: period_ns.max(1) as f64 / 1e9,
        }
    }

    /// The tick shown.
    pub fn tick(&self) -> u64 {
        self.at as u64
    }

    /// Moves on by `wall` of wall-clock time while playing; at the last tick it pauses.
    pub fn advance(&mut self, wall: Duration) {
        if !self.playing {
            return;
        }
        self.at += wall.as_secs_f64() * self.speed / self.step_s;
        if self.at >= self.last as f64 {
            self.at = self.last as f64;
            self.playing = false;
        }
    }

    /// Plays from where it is; from the first tick again once at the last.
    pub fn play(&mut self) {
        if self.tick() >= self.last {
            self.at = self.first as f64;
        }
        self.playing = true;
    }

    pub fn pause(&mut self) {
        self.playing = false;
    }

    /// Goes to `tick`, clamped to the recording's; playing or paused as before.
    pub fn seek(&mut self, tick: u64) {
        self.at = tick.clamp(self.first, self.last) as f64;
    }

    /// Plays `speed` times as fast as recorded, clamped to [`MIN_SPEED`]..=[`MAX_SPEED`] (NaN
    /// leaves it as it was).
    pub fn set_speed(&mut self, speed: f64) {
        if !speed.is_nan() {
            self.speed = speed.clamp(MIN_SPEED, MAX_SPEED);
        }
    }

    /// Does what a page asked.
    pub fn apply(&mut self, op: TimelineOp) {
        match op {
            TimelineOp::Play => self.play(),
            TimelineOp::Pause => self.pause(),
            TimelineOp::Seek { tick } => self.seek(tick),
            TimelineOp::Speed { speed } => self.set_speed(speed),
        }
    }

    pub fn timeline(&self) -> Timeline {
        Timeline {
            first_tick: self.first,
            last_tick: self.last,
            tick: self.tick(),
            playing: self.playing,
            speed: self.speed,
        }
    }
}

/// One topic's samples in tick order (those of one tick in the order recorded), each kept
/// without its trailing zero bytes (the unused end of a grid's, a cloud's or a scan's array).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Track {
    ticks: Vec<u64>,
    samples: Vec<Box<[u8]>>,
}

impl Track {
    /// Adds a sample of `tick` after every sample of that tick or an earlier one.
    pub fn push(&mut self, tick: u64, data: &[u8]) {
        let used = data.iter().rposition(|b| *b != 0).map_or(0, |i| i + 1);
        let at = self.ticks.partition_point(|t| *t <= tick);
        self.ticks.insert(at, tick);
        self.samples.insert(at, data[..used].into());
    }

    pub fn len(&self) -> usize {
        self.ticks.len()
    }

    pub fn is_empty(&self) -> bool {
        self.ticks.is_empty()
    }

    /// The first and last tick, `None` when empty.
    pub fn span(&self) -> Option<(u64, u64)> {
        Some((*self.ticks.first()?, *self.ticks.last()?))
    }

    /// The newest sample at or before `tick` (the last recorded of its tick).
    pub fn newest_at(&self, tick: u64) -> Option<&[u8]> {
        let after = self.ticks.partition_point(|t| *t <= tick);
        after.checked_sub(1).map(|i| &*self.samples[i])
    }

    /// The samples of ticks `from..=to`, in order, with their ticks.
    pub fn within(&self, from: u64, to: u64) -> impl Iterator<Item = (u64, &[u8])> {
        let start = self.ticks.partition_point(|t| *t < from);
        let end = self.ticks.partition_point(|t| *t <= to).max(start);
        self.ticks[start..end]
            .iter()
            .copied()
            .zip(self.samples[start..end].iter().map(|s| &**s))
    }
}

/// A message of type `M` from a track's bytes (the trimmed zeros restored), on the heap: a grid
/// or a particle set is too large for a thread's stack.
fn decoded<M: Message>(bytes: &[u8]) -> Box<M> {
    let mut message: Box<M> = bytemuck::zeroed_box();
    bytemuck::bytes_of_mut(&mut *message)[..bytes.len()].copy_from_slice(bytes);
    message
}

/// Decodes a recorded message and checks its values as a subscriber would.
fn checked<M: Message>(bytes: &[u8]) -> Result<Box<M>, String> {
    let message = decoded::<M>(bytes);
    message.validate().map_err(|e| e.to_string())?;
    Ok(message)
}

/// Why a recording cannot be shown.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReelError {
    /// Missing, not MCAP, truncated, corrupt, not mole's, other layouts: what replay says.
    #[error(transparent)]
    Tape(#[from] TapeError),
    #[error("{}: `{topic}` at tick {tick} holds invalid values ({why})", path.display())]
    Invalid {
        path: PathBuf,
        topic: String,
        tick: u64,
        why: String,
    },
    #[error("{}: {what}; expected a recording of a run (`mole up --record FILE`)", path.display())]
    Incomplete { path: PathBuf, what: String },
}

/// Every topic the view shows: the topic table's `shown` column.
pub fn shown() -> Vec<&'static str> {
    topics::policies()
        .into_iter()
        .filter(|p| p.shown)
        .map(|p| p.name)
        .collect()
}

/// A recording's shown topics in memory, each indexed by the world tick it was recorded at
/// (its log time over the step: the header's tick for the topics a step publishes, the newest
/// world tick the recorder had read for stack/stats and stack/processes).
#[derive(Debug, Clone, PartialEq)]
pub struct Reel {
    /// The recorded clock mode's name (`lockstep`, `realtime`).
    pub mode: &'static str,
    pub period_ns: u64,
    map: Option<Box<WorldMap>>,
    truth: Track,
    pose: Track,
    scan: Track,
    particles: Track,
    landmarks: Track,
    plan: Track,
    grid: Track,
    contact: Track,
    stats: Track,
    processes: Track,
    faults: Track,
    params: Track,
}

impl Reel {
    /// Reads the recording at `path`: refused, naming the file and what is wrong, when it is
    /// missing, not a finished mole recording of this build's layouts, holds a sample of
    /// invalid values, or lacks the world's map, its step or any truth.
    pub fn read(path: &Path) -> Result<Reel, ReelError> {
        let tape = read_tape(path, &[], Window::ALL)?;
        let incomplete = |what: &str| ReelError::Incomplete {
            path: path.to_path_buf(),
            what: what.to_string(),
        };
        let period_ns = tape
            .fact("period_ns")
            .and_then(|p| p.parse().ok())
            .filter(|p| *p > 0)
            .ok_or_else(|| incomplete("no simulated step (`period_ns`) in its `mole` metadata"))?;
        let mode = tape
            .fact("clock_mode")
            .and_then(|m| m.parse::<ClockMode>().ok())
            .map_or("unknown", ClockMode::name);
        let mut reel = Reel::empty(mode, period_ns);
        let mut invalid = None;
        for_each_sample(path, &shown(), |sample| {
            if invalid.is_none()
                && let Err(why) = reel.add(&sample)
            {
                invalid = Some(ReelError::Invalid {
                    path: path.to_path_buf(),
                    topic: sample.topic,
                    tick: sample.tick,
                    why,
                });
            }
        })?;
        if let Some(invalid) = invalid {
            return Err(invalid);
        }
        if reel.map.is_none() {
            return Err(incomplete("no `world/map` (the arena) recorded"));
        }
        if reel.truth.is_empty() {
            return Err(incomplete("no `world/truth` recorded"));
        }
        Ok(reel)
    }

    /// A reel of no samples yet, recorded in clock `mode` with steps of `period_ns` (> 0).
    pub fn empty(mode: &'static str, period_ns: u64) -> Reel {
        Reel {
            mode,
            period_ns: period_ns.max(1),
            map: None,
            truth: Track::default(),
            pose: Track::default(),
            scan: Track::default(),
            particles: Track::default(),
            landmarks: Track::default(),
            plan: Track::default(),
            grid: Track::default(),
            contact: Track::default(),
            stats: Track::default(),
            processes: Track::default(),
            faults: Track::default(),
            params: Track::default(),
        }
    }

    /// Adds one recorded sample of a shown topic (others are ignored); one whose values a
    /// subscriber would refuse is refused with the reason.
    pub fn add(&mut self, sample: &Sample) -> Result<(), String> {
        let tick = sample.log_time / self.period_ns;
        let data = &sample.data;
        let topic = sample.topic.as_str();
        if topic == topics::WORLD_MAP.name {
            self.map = Some(checked::<WorldMap>(data)?);
            return Ok(());
        }
        let (track, check): (&mut Track, Check) = match topic {
            t if t == topics::WORLD_TRUTH.name => (&mut self.truth, |d| valid::<Truth>(d)),
            t if t == topics::LOCALIZATION_POSE.name => (&mut self.pose, |d| valid::<Pose>(d)),
            t if t == topics::SENSING_SCAN.name => (&mut self.scan, |d| valid::<Scan>(d)),
            t if t == topics::LOCALIZATION_PARTICLES.name => {
                (&mut self.particles, |d| valid::<Particles>(d))
            }
            t if t == topics::LOCALIZATION_LANDMARKS.name => {
                (&mut self.landmarks, |d| valid::<Landmarks>(d))
            }
            t if t == topics::PLANNING_STATUS.name => (&mut self.plan, |d| valid::<PlanStatus>(d)),
            t if t == topics::MAPPING_GRID.name => (&mut self.grid, |d| valid::<Grid>(d)),
            t if t == topics::MAPPING_CONTACT.name => (&mut self.contact, |d| valid::<Grid>(d)),
            t if t == topics::STACK_STATS.name => (&mut self.stats, |d| valid::<Stats>(d)),
            t if t == topics::STACK_PROCESSES.name => {
                (&mut self.processes, |d| valid::<Processes>(d))
            }
            t if t == topics::STACK_FAULTS.name => (&mut self.faults, |d| valid::<Fault>(d)),
            t if t == topics::STACK_PARAMS.name => (&mut self.params, |d| valid::<ParamChange>(d)),
            _ => return Ok(()),
        };
        check(data)?;
        track.push(tick, data);
        Ok(())
    }

    /// The first and last tick of the recorded truths (`(0, 0)` for none).
    pub fn span(&self) -> (u64, u64) {
        self.truth.span().unwrap_or((0, 0))
    }

    /// How far back of a tick the scene's moving windows reach (ticks): the loop latency's
    /// window or the truths a scan is drawn from, the longer. A jump forwards further than this
    /// rebuilds the scene.
    pub fn history(&self) -> u64 {
        let latency = (LATENCY_WINDOW_S * 1e9 / self.period_ns as f64).round() as u64;
        latency.max(TRUTHS_KEPT as u64)
    }

    /// The scene at `tick`, made afresh (see the module's description); `None` without a map.
    pub fn scene_at(&self, tick: u64) -> Option<Scene> {
        let mut scene = Scene::new(self.map.as_deref()?, self.mode, false);
        for (_, truth) in self.truth.within(tick.saturating_sub(self.history()), tick) {
            scene.on_truth(&decoded(truth));
        }
        self.newest(&mut scene, |track| track.newest_at(tick));
        self.reports(&mut scene, 0, tick);
        Some(scene)
    }

    /// Feeds `scene` what was recorded after tick `after` up to `upto`: every truth, statistics
    /// report and process table, the newest of every other topic.
    pub fn feed(&self, scene: &mut Scene, after: u64, upto: u64) {
        let from = after.saturating_add(1);
        for (_, truth) in self.truth.within(from, upto) {
            scene.on_truth(&decoded(truth));
        }
        self.newest(scene, |track| {
            track.within(from, upto).last().map(|(_, s)| s)
        });
        self.reports(scene, from, upto);
    }

    /// Hands `scene` the sample `pick` chooses of every topic of which only the newest counts.
    fn newest<'a>(&'a self, scene: &mut Scene, pick: impl Fn(&'a Track) -> Option<&'a [u8]>) {
        if let Some(pose) = pick(&self.pose) {
            scene.on_pose(&decoded(pose));
        }
        if let Some(scan) = pick(&self.scan) {
            scene.on_scan(&decoded(scan));
        }
        if let Some(particles) = pick(&self.particles) {
            scene.on_particles(&decoded(particles));
        }
        if let Some(landmarks) = pick(&self.landmarks) {
            scene.on_landmarks(&decoded(landmarks));
        }
        if let Some(plan) = pick(&self.plan) {
            scene.on_plan(&decoded(plan));
        }
        for grid in [&self.grid, &self.contact] {
            if let Some(grid) = pick(grid) {
                scene.on_grid(&decoded(grid));
            }
        }
    }

    /// Hands `scene` every statistics report and process table of ticks `from..=to`.
    fn reports(&self, scene: &mut Scene, from: u64, to: u64) {
        for (_, stats) in self.stats.within(from, to) {
            scene.on_stats(&decoded(stats));
        }
        // Process tables and faults in the order they were recorded, as their events came.
        let mut processes = self.processes.within(from, to).peekable();
        let mut faults = self.faults.within(from, to).peekable();
        loop {
            match (processes.peek(), faults.peek()) {
                (Some(&(p, _)), Some(&(f, _))) if f < p => {
                    let (tick, fault) = faults.next().expect("peeked");
                    scene.on_fault_at(&decoded(fault), tick);
                }
                (Some(_), _) => {
                    let (tick, report) = processes.next().expect("peeked");
                    scene.on_processes_at(&decoded(report), tick);
                }
                (None, Some(_)) => {
                    let (tick, fault) = faults.next().expect("peeked");
                    scene.on_fault_at(&decoded(fault), tick);
                }
                (None, None) => break,
            }
        }
        for (tick, change) in self.params.within(from, to) {
            scene.on_param_at(&decoded(change), tick);
        }
    }
}

/// Whether recorded bytes hold valid values of one message type.
type Check = fn(&[u8]) -> Result<(), String>;

/// Whether recorded bytes hold valid values of `M`.
fn valid<M: Message>(bytes: &[u8]) -> Result<(), String> {
    checked::<M>(bytes).map(drop)
}

/// A recording played: the clock, and the scene fed up to its tick.
pub struct Playback {
    reel: Reel,
    pub clock: Clock,
    scene: Scene,
    /// The tick the scene was fed up to.
    fed: u64,
    frames: u64,
}

impl Playback {
    /// The recording shown from its first tick, paused; `None` without a map.
    pub fn new(reel: Reel) -> Option<Playback> {
        let (first, last) = reel.span();
        let scene = reel.scene_at(first)?;
        Some(Playback {
            clock: Clock::new(first, last, reel.period_ns),
            reel,
            scene,
            fed: first,
            frames: 0,
        })
    }

    /// The frame at the clock's tick: the scene fed forwards up to it, or rebuilt for a seek
    /// backwards or a jump beyond [`Reel::history`].
    pub fn frame(&mut self, rejected_inputs: u64) -> Frame {
        let tick = self.clock.tick();
        if tick < self.fed || tick - self.fed > self.reel.history() {
            if let Some(scene) = self.reel.scene_at(tick) {
                self.scene = scene;
            }
        } else if tick > self.fed {
            self.reel.feed(&mut self.scene, self.fed, tick);
        }
        self.fed = tick;
        self.frames += 1;
        let mut frame = self.scene.frame(rejected_inputs);
        // A rebuilt scene counts its frames afresh; the page's count goes on.
        frame.state.seq = self.frames;
        frame.state.timeline = Some(self.clock.timeline());
        frame
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Client;
    use crate::tests::{grid, map, truth, zeroed};
    use mole_types::{FaultKind, FaultSpec, GRID_FRONTIER, PROCESS_RUNNING, write_name};
    use serde_json::Value;

    const PERIOD_NS: u64 = 10_000_000;

    /// A recorded sample of `message` on `topic`, logged at world tick `at`.
    fn sample<M: Message>(topic: &str, at: u64, message: &M) -> Sample {
        Sample {
            topic: topic.to_string(),
            tick: message.header().tick,
            log_time: at * PERIOD_NS,
            data: bytemuck::bytes_of(message).to_vec(),
        }
    }

    /// The topic table's `shown` column and the reel agree: a sample of every shown topic is
    /// read (kept, or refused for its values), one of any other is passed by.
    #[test]
    fn the_reel_reads_every_shown_topic_and_only_those() {
        let shown = shown();
        assert!(shown.contains(&topics::MAPPING_GRID.name), "{shown:?}");
        for (topic, _) in topics::all() {
            let mut reel = Reel::empty("lockstep", PERIOD_NS);
            let sample = Sample {
                topic: topic.to_string(),
                tick: 1,
                log_time: PERIOD_NS,
                data: vec![1, 2, 3],
            };
            let refused = reel.add(&sample).is_err();
            let tracks = [
                &reel.truth,
                &reel.pose,
                &reel.scan,
                &reel.particles,
                &reel.landmarks,
                &reel.plan,
                &reel.grid,
                &reel.contact,
                &reel.stats,
                &reel.processes,
                &reel.faults,
                &reel.params,
            ];
            let kept = reel.map.is_some() || tracks.iter().any(|t| !t.ticks.is_empty());
            let read = refused || kept;
            assert_eq!(read, shown.contains(&topic), "{topic}: read {read}");
        }
    }

    /// The process table of one role, `sensing`, with its pid and restarts.
    fn processes(pid: u32, restarts: u32) -> Box<Processes> {
        let mut report: Box<Processes> = zeroed();
        report.n_processes = 1;
        write_name(&mut report.processes[0].role, "sensing");
        let p = &mut report.processes[0];
        (p.pid, p.state, p.restarts) = (pid, PROCESS_RUNNING, restarts);
        report
    }

    /// 600 steps: a truth (x = tick) and an estimate each, a grid every 10 ticks with cell
    /// tick / 10 free, and sensing's table (header tick 0, as the launcher's) logged at ticks 250
    /// (started) and 450 (restarted).
    fn reel() -> Reel {
        let mut reel = Reel::empty("lockstep", PERIOD_NS);
        reel.add(&sample(topics::WORLD_MAP.name, 0, &*map()))
            .expect("map");
        for tick in 0..=600 {
            let add = |reel: &mut Reel, s: Sample| reel.add(&s).expect("a valid sample");
            add(
                &mut reel,
                sample(
                    topics::WORLD_TRUTH.name,
                    tick,
                    &*truth(tick, tick as f64, 1000 + tick),
                ),
            );
            let mut pose: Box<Pose> = zeroed();
            (pose.header.tick, pose.x) = (tick, tick as f64 + 0.5);
            add(
                &mut reel,
                sample(topics::LOCALIZATION_POSE.name, tick, &*pose),
            );
            if tick % 10 == 0 {
                let mut g = grid(GRID_FRONTIER, tick, 20, 10);
                g.cells[(tick / 10) as usize] = 1;
                add(&mut reel, sample(topics::MAPPING_GRID.name, tick, &*g));
            }
        }
        for (at, pid, restarts) in [(250, 40, 0), (450, 41, 1)] {
            let report = processes(pid, restarts);
            reel.add(&sample(topics::STACK_PROCESSES.name, at, &*report))
                .expect("processes");
        }
        let mut fault: Box<Fault> = zeroed();
        let kill = FaultSpec {
            kind: FaultKind::Kill,
            target: "planning".into(),
            duration_s: 0.0,
            delay_ms: 0.0,
            fraction: 0.0,
        };
        kill.to_message(&mut fault, 1, 0, 0);
        reel.add(&sample(topics::STACK_FAULTS.name, 350, &*fault))
            .expect("a fault");
        let mut change: Box<ParamChange> = zeroed();
        (change.state, change.apply_at) = (mole_types::PARAM_APPLIED, 479);
        write_name(&mut change.role, "planning");
        write_name(&mut change.key, "dwa.critics.heading");
        write_name(&mut change.value, "0.4");
        reel.add(&sample(topics::STACK_PARAMS.name, 480, &*change))
            .expect("a setting changed");
        reel
    }

    /// A seek is clamped to the recording's ticks; the speed to 0.1×–20× (NaN changes nothing).
    #[test]
    fn the_clock_clamps_seeks_and_its_speed() {
        let mut clock = Clock::new(100, 700, PERIOD_NS);
        assert_eq!((clock.tick(), clock.timeline().playing), (100, false));
        clock.seek(5);
        assert_eq!(clock.tick(), 100);
        clock.seek(10_000);
        assert_eq!(clock.tick(), 700);
        clock.seek(321);
        assert_eq!(clock.tick(), 321);
        clock.set_speed(50.0);
        assert_eq!(clock.timeline().speed, MAX_SPEED);
        clock.set_speed(0.01);
        assert_eq!(clock.timeline().speed, MIN_SPEED);
        clock.set_speed(f64::NAN);
        assert_eq!(clock.timeline().speed, MIN_SPEED);
        clock.apply(TimelineOp::Speed { speed: 4.0 });
        assert_eq!(clock.timeline().speed, 4.0);
    }

    /// Paused, the clock holds whatever the wall clock does; playing, it moves `speed` steps of
    /// simulated time per wall second's step, stops at the last tick, and plays again from the
    /// first.
    #[test]
    fn a_paused_clock_holds_and_a_playing_one_moves_by_its_speed() {
        let mut clock = Clock::new(100, 700, PERIOD_NS);
        clock.advance(Duration::from_secs(3));
        assert_eq!(clock.tick(), 100);
        clock.apply(TimelineOp::Speed { speed: 10.0 });
        clock.apply(TimelineOp::Play);
        clock.advance(Duration::from_millis(500));
        assert_eq!(clock.tick(), 600, "0.5 s at 10× is 5 simulated s");
        clock.apply(TimelineOp::Pause);
        clock.advance(Duration::from_secs(1));
        assert_eq!(clock.tick(), 600);
        clock.play();
        clock.advance(Duration::from_secs(1));
        assert_eq!(
            clock.timeline(),
            Timeline {
                first_tick: 100,
                last_tick: 700,
                tick: 700,
                playing: false,
                speed: 10.0
            }
        );
        clock.play();
        assert_eq!((clock.tick(), clock.timeline().playing), (100, true));
    }

    /// The newest sample at or before a tick, by binary search, whatever order they came in;
    /// a range holds its ticks' samples in order; trimmed zeros come back.
    #[test]
    fn a_track_finds_the_newest_sample_at_or_before_a_tick() {
        let mut track = Track::default();
        track.push(30, &[3, 0, 0]);
        track.push(10, &[1]);
        track.push(20, &[2, 0, 7, 0]);
        track.push(20, &[22]);
        assert_eq!(track.len(), 4);
        assert_eq!(track.span(), Some((10, 30)));
        assert_eq!(track.newest_at(9), None);
        assert_eq!(track.newest_at(10), Some(&[1u8][..]));
        assert_eq!(
            track.newest_at(25),
            Some(&[22u8][..]),
            "the last of tick 20"
        );
        assert_eq!(track.newest_at(u64::MAX), Some(&[3u8][..]));
        let ticks: Vec<u64> = track.within(11, 30).map(|(t, _)| t).collect();
        assert_eq!(ticks, [20, 20, 30]);
        assert_eq!(track.within(31, 40).count(), 0);
        assert_eq!(track.within(20, 10).count(), 0);
        let stored = track.within(20, 20).next().map(|(_, s)| s);
        assert_eq!(stored, Some(&[2u8, 0, 7][..]));
        let mut t = truth(5, 1.25, 0);
        t.theta = 0.0;
        let mut truths = Track::default();
        truths.push(5, bytemuck::bytes_of(&*t));
        assert_eq!(*decoded::<Truth>(truths.newest_at(5).expect("truth")), *t);
    }

    /// A seek far forwards rebuilds the scene a forward feed makes (but the frame count); a
    /// seek backwards forgets what came after (events included); events stand at the tick they
    /// were logged at, not their header's.
    #[test]
    fn a_seek_rebuilds_what_playing_forwards_shows() {
        let mut played = Playback::new(reel()).expect("a map");
        for tick in (0..=500).step_by(50) {
            played.clock.seek(tick);
            played.frame(0);
        }
        let forwards = played.frame(0);
        let mut sought = Playback::new(reel()).expect("a map");
        sought.frame(0);
        sought.clock.seek(500);
        let rebuilt = sought.frame(0);
        assert_eq!(rebuilt.state.seq, 2);
        let same = |f: &Frame| (f.state.clone(), f.frontier.clone());
        let (mut a, mut b) = (same(&forwards), same(&rebuilt));
        (a.0.seq, b.0.seq) = (0, 0);
        assert_eq!(a, b);
        let s = &rebuilt.state;
        assert_eq!(s.truth.map(|t| (t.tick, t.x)), Some((500, 500.0)));
        assert_eq!(s.pose.map(|p| p.x), Some(500.5));
        assert_eq!(
            rebuilt.frontier.as_ref().map(|g| (g.tick, g.cells[50])),
            Some((500, 1))
        );
        assert_eq!(s.latency.map(|l| l.samples), Some(201), "the 2 s window");
        let events: Vec<(&Value, &Value)> =
            s.events.iter().map(|e| (&e["kind"], &e["tick"])).collect();
        assert_eq!(s.events_total, 4);
        assert_eq!(
            events,
            [
                (&"started".into(), &250.into()),
                (&"fault".into(), &350.into()),
                (&"restarted".into(), &450.into()),
                (&"param".into(), &480.into())
            ]
        );
        assert_eq!(s.events[1]["target"], "planning");
        assert_eq!(
            (
                &s.events[3]["key"],
                &s.events[3]["applied"],
                &s.events[3]["at"]
            ),
            (&"dwa.critics.heading".into(), &true.into(), &479.into())
        );
        assert_eq!(
            s.timeline.map(|t| (t.first_tick, t.tick, t.last_tick)),
            Some((0, 500, 600))
        );

        sought.clock.seek(300);
        let back = sought.frame(0);
        assert_eq!(back.state.truth.map(|t| t.tick), Some(300));
        assert_eq!(
            back.frontier.as_ref().map(|g| (g.tick, g.cells[30])),
            Some((300, 1))
        );
        assert_eq!(
            back.state.events_total, 1,
            "the restart at 450 is still to come"
        );
        sought.clock.seek(320);
        let on = sought.frame(0);
        assert_eq!(on.state.truth.map(|t| t.tick), Some(320));
        assert_eq!(on.state.pose.map(|p| p.tick), Some(320));
    }

    /// Only a recording's frame carries a timeline.
    #[test]
    fn only_a_recordings_frame_has_a_timeline() {
        let mut playback = Playback::new(reel()).expect("a map");
        let message = Client::default().message(&playback.frame(0));
        let sent: serde_json::Value = serde_json::from_str(&message).expect("JSON");
        assert_eq!(sent["timeline"]["last_tick"], 600);
        assert_eq!(sent["timeline"]["playing"], false);
        assert_eq!(sent["controls"], false);
        let mut live = Scene::new(&map(), "lockstep", true);
        let message = Client::default().message(&live.frame(0));
        let sent: serde_json::Value = serde_json::from_str(&message).expect("JSON");
        assert!(sent.get("timeline").is_none(), "{sent}");
    }

    /// A sample a subscriber would refuse (a NaN pose) is refused, with the reason.
    #[test]
    fn a_sample_of_invalid_values_is_refused() {
        let mut reel = Reel::empty("lockstep", PERIOD_NS);
        let bad = truth(3, f64::NAN, 0);
        let refused = reel
            .add(&sample(topics::WORLD_TRUTH.name, 3, &*bad))
            .expect_err("NaN");
        assert!(refused.contains("not finite"), "{refused}");
        assert!(reel.truth.is_empty());
    }
}
