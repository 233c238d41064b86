//! The frame a scene makes from samples, and the messages one page is sent.

use crate::{Client, Frame, MAX_PARTICLES_SENT, Scene, TILE};
use mole_types::{
    GRID_CONTACT, GRID_FRONTIER, Grid, Landmarks, PROCESS_RUNNING, Particles, PlanStatus, Pose,
    Processes, STATUS_HAS_FRONTIER, Scan, Stats, TRUTH_END, Truth, WorldMap, write_name,
};
use serde_json::Value;

pub(crate) fn zeroed<T: bytemuck::Zeroable>() -> Box<T> {
    bytemuck::zeroed_box()
}

pub(crate) fn map() -> Box<WorldMap> {
    let mut map: Box<WorldMap> = zeroed();
    (map.arena_width, map.arena_height, map.dt) = (10.0, 8.0, 0.01);
    map.grid_resolution = 0.1;
    map.robot.radius = 0.2;
    map.n_obstacles = 1;
    (
        map.obstacles[0].cx,
        map.obstacles[0].cy,
        map.obstacles[0].side,
    ) = (3.0, 4.0, 1.0);
    map
}

pub(crate) fn truth(tick: u64, x: f64, latency_ns: u64) -> Box<Truth> {
    let mut t: Box<Truth> = zeroed();
    t.header.tick = tick;
    (t.x, t.y, t.theta) = (x, 2.0, 0.5);
    t.cmd_latency_ns = latency_ns;
    t
}

pub(crate) fn grid(kind: u32, tick: u64, w: u32, h: u32) -> Box<Grid> {
    let mut g: Box<Grid> = zeroed();
    g.header.tick = tick;
    (g.width, g.height, g.resolution, g.kind) = (w, h, 0.1, kind);
    g
}

fn json(text: &str) -> Value {
    serde_json::from_str(text).expect("a message is JSON")
}

/// A scene fed one sample of every shown topic.
fn scene() -> Scene {
    let mut scene = Scene::new(&map(), "lockstep", true);
    for tick in 1..=5 {
        scene.on_truth(&truth(tick, tick as f64, 1000 * tick));
    }
    let mut pose: Box<Pose> = zeroed();
    pose.header.tick = 5;
    (pose.x, pose.y) = (4.9, 2.1);
    pose.covariance = [0.04, 0.01, 0.0, 0.01, 0.09, 0.0, 0.0, 0.0, 0.2];
    scene.on_pose(&pose);
    let mut scan: Box<Scan> = zeroed();
    scan.header.tick = 3;
    (scan.n_beams, scan.range_max, scan.angle_increment) = (4, 6.0, 0.5);
    scan.ranges[..4].copy_from_slice(&[1.0, 2.0, 6.0, 3.0]);
    scene.on_scan(&scan);
    let mut particles: Box<Particles> = zeroed();
    particles.n_particles = 5000;
    particles.n_filter = particles.n_particles;
    for (i, p) in particles.particles[..5000].iter_mut().enumerate() {
        p.x = i as f32;
    }
    scene.on_particles(&particles);
    let mut landmarks: Box<Landmarks> = zeroed();
    landmarks.n_landmarks = 1;
    landmarks.landmarks[0].id = 7;
    landmarks.landmarks[0].covariance = [0.5, 0.1, 0.1, 0.3];
    scene.on_landmarks(&landmarks);
    let mut plan: Box<PlanStatus> = zeroed();
    plan.flags = STATUS_HAS_FRONTIER;
    (plan.frontier_x, plan.frontier_y, plan.n_path) = (6.0, 7.0, 2);
    plan.path[..2].copy_from_slice(&[[1.0, 2.0], [6.0, 7.0]]);
    scene.on_plan(&plan);
    scene.on_grid(&grid(GRID_FRONTIER, 5, 100, 80));
    scene.on_grid(&grid(GRID_CONTACT, 5, 100, 80));
    scene
}

/// A frame says what the samples said: the newest truth, the estimate with its position
/// covariance, the scan drawn from the truth at its own tick, the particles strided to the cap,
/// landmarks, plan, grids whole, latency over the window.
#[test]
fn the_frame_holds_what_the_samples_said() {
    let frame = scene().frame(3);
    let s = &frame.state;
    assert_eq!(
        (s.seq, s.tick, s.mode, s.controls),
        (1, 5, "lockstep", true)
    );
    assert!((s.time_s - 0.05).abs() < 1e-12);
    assert_eq!(s.truth.map(|t| (t.tick, t.x)), Some((5, 5.0)));
    assert_eq!(s.pose.map(|p| p.cov), Some([0.04, 0.01, 0.09]));
    let scan = s.scan.as_ref().expect("scan");
    assert_eq!((scan.x, scan.ranges.len()), (3.0, 4), "drawn from truth 3");
    let cloud = s.particles.as_ref().expect("particles");
    assert_eq!((cloud.total, cloud.stride), (5000, 3));
    assert!(cloud.xy.len() / 2 <= MAX_PARTICLES_SENT);
    assert_eq!(&cloud.xy[..4], &[0.0, 0.0, 3.0, 0.0]);
    assert_eq!(s.landmarks[0].id, Some(7));
    assert_eq!(s.landmarks[0].cov, [0.5, 0.1, 0.3]);
    let plan = s.plan.as_ref().expect("plan");
    assert_eq!((plan.goal, plan.frontier), (None, Some([6.0, 7.0])));
    let latency = s.latency.expect("latency");
    assert_eq!(
        (latency.samples, latency.p50_us, latency.p99_us),
        (5, 3.0, 5.0)
    );
    assert_eq!(frame.frontier.as_ref().map(|g| g.cells.len()), Some(8000));
    assert_eq!(frame.arena.obstacles, vec![[3.0, 4.0, 1.0]]);
    assert_eq!(s.rejected_inputs, 3);
    assert!(!s.ended);
}

/// The loop latency is over the moving window only: old commands leave it.
#[test]
fn latency_is_over_the_moving_window() {
    let mut scene = Scene::new(&map(), "realtime", false);
    scene.on_truth(&truth(1, 0.0, 1_000_000));
    scene.on_truth(&truth(1000, 0.0, 2000));
    let mut last = truth(1001, 0.0, 4000);
    last.flags = TRUTH_END;
    scene.on_truth(&last);
    let state = scene.frame(0).state;
    let latency = state.latency.expect("latency");
    assert_eq!((latency.samples, latency.p99_us), (2, 4.0));
    assert!(state.ended);
}

fn stats(process: &str, stamp_ns: u64, cpu_ns: u64) -> Box<Stats> {
    let mut s: Box<Stats> = zeroed();
    write_name(&mut s.process, process);
    s.header.stamp_ns = stamp_ns;
    s.cpu_ns = cpu_ns;
    s.n_topics = 1;
    write_name(&mut s.topics[0].topic, "sensing/scan");
    s.topics[0].direction = mole_types::DIRECTION_PUBLISH;
    s.topics[0].rate_hz = 99.5;
    s
}

/// CPU % is the CPU time between two reports over the wall time between them; rates are the
/// publishers'; a restart in stack/processes is an event.
#[test]
fn cpu_rates_and_events_come_from_the_stack_topics() {
    let mut scene = scene();
    scene.on_stats(&stats("sensing", 1_000_000_000, 5_000_000_000));
    scene.on_stats(&stats("sensing", 2_000_000_000, 5_250_000_000));
    let mut report: Box<Processes> = zeroed();
    report.n_processes = 1;
    write_name(&mut report.processes[0].role, "sensing");
    (report.processes[0].pid, report.processes[0].state) = (40, PROCESS_RUNNING);
    scene.on_processes(&report);
    (report.processes[0].pid, report.processes[0].restarts) = (41, 1);
    scene.on_processes(&report);
    let s = scene.frame(0).state;
    assert_eq!(s.cpu.len(), 1);
    assert!((s.cpu[0].percent - 25.0).abs() < 1e-9, "{:?}", s.cpu);
    assert_eq!(s.topics[0].topic, "sensing/scan");
    assert_eq!(s.topics[0].rate_hz, 99.5);
    assert_eq!(s.events_total, 2);
    assert_eq!(s.events[1]["kind"], "restarted");
    assert_eq!(s.events[1]["tick"], 5);
}

/// A page's first message holds the arena and the whole grids; the next, with one cell
/// changed, only that cell's tile and no arena; a frame with the same grid, no grid at all.
#[test]
fn a_page_gets_everything_first_then_changed_tiles() {
    let mut scene = scene();
    let mut client = Client::default();
    let first = json(&client.message(&scene.frame(0)));
    assert_eq!(first["type"], "frame");
    assert_eq!(first["full"], true);
    assert_eq!(first["arena"]["width"], 10.0);
    let frontier = &first["grids"]["frontier"];
    assert_eq!(frontier["whole"], true);
    assert_eq!(frontier["width"], 100);
    let tiles = frontier["tiles"].as_array().expect("tiles");
    assert_eq!(
        tiles.len(),
        100usize.div_ceil(TILE) * 80usize.div_ceil(TILE)
    );
    assert!(first["grids"]["contact"].is_object());
    assert_eq!(first["truth"]["tick"], 5);

    let mut next = grid(GRID_FRONTIER, 6, 100, 80);
    next.cells[41 * 100 + 70] = 1;
    scene.on_grid(&next);
    let second = json(&client.message(&scene.frame(0)));
    assert_eq!(second["full"], false);
    assert!(second.get("arena").is_none());
    let frontier = &second["grids"]["frontier"];
    assert_eq!(frontier["whole"], false);
    assert_eq!(frontier["tick"], 6);
    let tiles = frontier["tiles"].as_array().expect("tiles");
    assert_eq!(tiles.len(), 1);
    assert_eq!(
        (&tiles[0]["x"], &tiles[0]["y"]),
        (&Value::from(64), &Value::from(32))
    );
    assert!(
        second["grids"].get("contact").is_none(),
        "contact unchanged"
    );

    let third = json(&client.message(&scene.frame(0)));
    assert_eq!(third["grids"], serde_json::json!({}));
    assert_eq!(third["seq"], 3);
}

/// A page that connects later gets everything in its first message, whatever others got.
#[test]
fn a_late_page_starts_whole() {
    let mut scene = scene();
    let frame: Frame = scene.frame(0);
    let mut early = Client::default();
    early.message(&frame);
    let mut late = Client::default();
    let first = json(&late.message(&frame));
    assert_eq!(first["full"], true);
    assert_eq!(first["grids"]["frontier"]["whole"], true);
}
