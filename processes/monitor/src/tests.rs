//! Tests of the monitor against hand-made worlds whose answers can be counted by hand.

use super::*;
use approx::assert_relative_eq;
use mole_types::{
    DIRECTION_PUBLISH, GRID_CONTACT, GRID_FRONTIER, Header, LANDMARK_ANONYMOUS, MAX_GRID_CELLS,
    TRUTH_END, write_name,
};
use proptest::prelude::*;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::f64::consts::PI;

// ---------------------------------------------------------------------------------------------
// Allocation counting (per thread, so parallel tests do not disturb each other).
// ---------------------------------------------------------------------------------------------

struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn count() {
    let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations() -> u64 {
    ALLOCATIONS.with(|c| c.get())
}

// ---------------------------------------------------------------------------------------------
// Hand-made worlds
// ---------------------------------------------------------------------------------------------

/// A `w × h` m arena at `res` with the given squares, start and robot radius.
fn world(w: f64, h: f64, res: f64, radius: f64, squares: &[Square]) -> Box<WorldMap> {
    let mut map: Box<WorldMap> = bytemuck::zeroed_box();
    map.arena_width = w;
    map.arena_height = h;
    map.dt = 0.01;
    map.grid_resolution = res;
    map.robot.radius = radius;
    map.start_x = 0.5;
    map.start_y = 1.0;
    map.seed = 7;
    map.n_obstacles = squares.len() as u32;
    map.obstacles[..squares.len()].copy_from_slice(squares);
    map
}

/// 4 × 2 m at 0.25 m (16 × 8 cells): a 2 × 2-cell block at cols 7-8, rows 3-4, and a wall
/// over cols 11-12 that cuts off cols 13-15.
fn walled_world(radius: f64) -> Box<WorldMap> {
    let mut squares = vec![Square::new(2.0, 1.0, 0.5)];
    for y in [0.25, 0.75, 1.25, 1.75] {
        squares.push(Square::new(3.0, y, 0.5));
    }
    world(4.0, 2.0, 0.25, radius, &squares)
}

fn grid(kind: u32, w: u32, h: u32, res: f64, cell: impl Fn(usize, usize) -> u8) -> Box<Grid> {
    let mut g: Box<Grid> = bytemuck::zeroed_box();
    g.kind = kind;
    g.width = w;
    g.height = h;
    g.resolution = res;
    for row in 0..h as usize {
        for col in 0..w as usize {
            g.cells[row * w as usize + col] = cell(col, row);
        }
    }
    g
}

fn truth(tick: u64, x: f64, y: f64, theta: f64) -> Truth {
    let mut t: Truth = bytemuck::Zeroable::zeroed();
    t.header = Header {
        tick,
        ..Header::default()
    };
    t.x = x;
    t.y = y;
    t.theta = theta;
    t
}

fn pose(tick: u64, x: f64, y: f64, theta: f64, diag: [f64; 3]) -> Pose {
    let mut p: Pose = bytemuck::Zeroable::zeroed();
    p.header.tick = tick;
    p.x = x;
    p.y = y;
    p.theta = theta;
    p.covariance = [diag[0], 0.0, 0.0, 0.0, diag[1], 0.0, 0.0, 0.0, diag[2]];
    p.estimator = mole_types::EstimatorKind::Ekf.code();
    p
}

// ---------------------------------------------------------------------------------------------
// Ground truth and coverage
// ---------------------------------------------------------------------------------------------

#[test]
fn raster_and_reachable_area_of_the_walled_world() {
    let m = Monitor::new(&walled_world(0.1)).unwrap();
    assert_eq!(m.grid_size(), (16, 8));
    let r = &m.raster;
    let occupied = r.flags.iter().filter(|f| *f & OCCUPIED != 0).count();
    assert_eq!(occupied, 4 + 16, "block and wall");
    assert!(r.flags[r.index(7, 3)] & OCCUPIED != 0);
    assert!(
        r.flags[r.index(6, 3)] & OCCUPIED == 0,
        "touching the edge is no overlap"
    );
    // Left of the wall: 11 × 8 cells less the block; right of it is cut off.
    assert_eq!(m.reachable_free_cells(), 84);
    assert!(r.flags[r.index(14, 4)] & REACHABLE == 0);
}

#[test]
fn robot_radius_and_arena_edge_shrink_the_reachable_area() {
    // r = 0.3 m = 1.2 cells: the ring of cells next to the edge (1 cell from the outside) drops
    // out, diagonal neighbours (1.41 cells) stay.
    let m = Monitor::new(&world(4.0, 2.0, 0.25, 0.3, &[])).unwrap();
    assert_eq!(m.reachable_free_cells(), 14 * 6);
    // r = 0.2 m = 0.8 cells: every cell is more than that from the outside.
    let m = Monitor::new(&world(4.0, 2.0, 0.25, 0.2, &[])).unwrap();
    assert_eq!(m.reachable_free_cells(), 16 * 8);
}

#[test]
fn a_partial_last_column_counts_as_occupied() {
    // 1.1 m at 0.25 m: 5 columns, the last one 0.15 m inside the arena and 0.1 m outside.
    let m = Monitor::new(&world(1.1, 2.0, 0.25, 0.05, &[])).unwrap();
    assert_eq!(m.grid_size(), (5, 8));
    let r = &m.raster;
    assert!((0..8).all(|row| r.flags[r.index(4, row)] & OCCUPIED != 0));
    assert_eq!(m.reachable_free_cells(), 4 * 8);
}

#[test]
fn coverage_is_the_explored_fraction_of_the_reachable_cells() {
    let mut m = Monitor::new(&walled_world(0.1)).unwrap();
    assert_eq!(m.coverage(), 0.0, "before any grid");
    // Explored: cols 0-4 free (40 cells), col 5 rows 0-1 wrongly marked occupied (still
    // explored), the unreachable right part free, wall and block occupied: 42 of 84 count.
    let g = grid(GRID_FRONTIER, 16, 8, 0.25, |col, row| match (col, row) {
        (0..=4, _) => 1,
        (5, 0..=1) => 2,
        (7..=8, 3..=4) | (11..=12, _) => 2,
        (13.., _) => 1,
        _ => 0,
    });
    m.on_grid(&g);
    assert_eq!(m.coverage(), 0.5);
    assert_eq!(m.ignored_messages(), 0);
}

#[test]
fn coverage_milestones_are_checked_every_ten_steps_and_on_the_last_grid() {
    let mut m = Monitor::new(&walled_world(0.1)).unwrap();
    // Reachable: cols 0-10 less the block, 84 cells; `cols` explored columns from col 0.
    let explored = |tick: u64, cols: usize| {
        let mut g = grid(GRID_FRONTIER, 16, 8, 0.25, |col, _| u8::from(col < cols));
        g.header.tick = tick;
        g
    };
    m.on_grid(&explored(7, 6)); // 48 of 84: below 50%
    m.on_grid(&explored(13, 8)); // 50% passed here, but 13 is not checked
    m.on_grid(&explored(20, 8));
    m.on_grid(&explored(23, 11)); // 100%, the last grid of the run
    let steps = &m.summary(&meta()).coverage_steps;
    assert_eq!(
        steps["0.5"],
        Some(20),
        "the first checked step at or above 50%"
    );
    assert_eq!(steps["0.9"], Some(23), "the last grid counts too");
    assert_eq!(steps["0.95"], Some(23));
}

#[test]
fn a_start_cell_inside_the_clearance_seeds_from_the_nearest_free_cell() {
    // Start in the corner cell, which a 0.3 m robot cannot occupy at 0.25 m cells.
    let mut map = world(4.0, 2.0, 0.25, 0.3, &[]);
    map.start_x = 0.1;
    map.start_y = 0.1;
    let m = Monitor::new(&map).unwrap();
    assert_eq!(m.reachable_free_cells(), 14 * 6);
}

#[test]
fn bad_maps_are_refused() {
    let mut map = world(4.0, 2.0, 0.25, 0.1, &[]);
    map.grid_resolution = 0.0;
    assert!(matches!(
        Monitor::new(&map),
        Err(MonitorError::InvalidMap(_))
    ));
    let mut map = world(4.0, 2.0, 0.25, 0.1, &[]);
    map.grid_resolution = 0.001;
    assert!(matches!(
        Monitor::new(&map),
        Err(MonitorError::GridTooLarge { .. })
    ));
    let mut map = world(4.0, 2.0, 0.25, 0.1, &[]);
    map.n_obstacles = u32::MAX;
    assert!(Monitor::new(&map).is_err());
}

// ---------------------------------------------------------------------------------------------
// Map quality
// ---------------------------------------------------------------------------------------------

#[test]
fn contact_precision_counts_cells_within_one_cell_of_truth() {
    let mut m = Monitor::new(&walled_world(0.1)).unwrap();
    assert_eq!(m.contact_map_precision(), None);
    // (7,3) in the block, (6,3) next to it, (0,5) next to the arena edge: true;
    // (3,4) in open space: false.
    let g = grid(GRID_CONTACT, 16, 8, 0.25, |col, row| {
        u8::from(matches!((col, row), (7, 3) | (6, 3) | (0, 5) | (3, 4)))
    });
    m.on_contact(&g);
    assert_eq!(m.contact_map_precision(), Some(0.75));
    // An empty contact grid has no precision.
    m.on_contact(&grid(GRID_CONTACT, 16, 8, 0.25, |_, _| 0));
    assert_eq!(m.contact_map_precision(), None);
}

#[test]
fn iou_is_taken_over_explored_cells_only() {
    let mut m = Monitor::new(&walled_world(0.1)).unwrap();
    assert_eq!(m.map_iou(), None);
    // Explored: cols 0-10. Three of the four block cells found, one missed, one false
    // obstacle at (2,2). The wall (cols 11-12) is unexplored and costs nothing.
    let g = grid(GRID_FRONTIER, 16, 8, 0.25, |col, row| match (col, row) {
        (7, 3) | (8, 3) | (7, 4) | (2, 2) => 2,
        (0..=10, _) => 1,
        _ => 0,
    });
    m.on_grid(&g);
    assert_relative_eq!(m.map_iou().unwrap(), 3.0 / 5.0);
    assert_eq!(m.coverage(), 1.0);
    // Explored free space with no obstacle on either side: undefined.
    m.on_grid(&grid(GRID_FRONTIER, 16, 8, 0.25, |col, _| {
        u8::from(col < 3)
    }));
    assert_eq!(m.map_iou(), None);
}

// ---------------------------------------------------------------------------------------------
// Localisation
// ---------------------------------------------------------------------------------------------

#[test]
fn rmse_and_nees_against_synthetic_poses() {
    let mut m = Monitor::new(&walled_world(0.1)).unwrap();
    assert_eq!(m.localization_rmse(), None);
    assert_eq!(m.mean_nees(), None);
    let cov = [0.09, 0.16, 0.01];
    for tick in 1..=3 {
        m.on_truth(&truth(tick, tick as f64, 0.0, PI - 0.05));
        // Error (0.3, 0.4, +0.1 across the ±π seam): 0.25 m², NEES 1 + 1 + 1.
        m.on_pose(&pose(tick, tick as f64 + 0.3, 0.4, -PI + 0.05, cov));
    }
    // A pose that arrives before its truth is matched when the truth comes.
    m.on_pose(&pose(4, 4.3, 0.4, -PI + 0.05, cov));
    m.on_truth(&truth(4, 4.0, 0.0, PI - 0.05));
    // A singular covariance: counted in the RMSE, not in the NEES.
    m.on_truth(&truth(5, 5.0, 0.0, 0.0));
    m.on_pose(&pose(5, 5.3, -0.4, 0.0, [0.0; 3]));
    // A pose whose truth never comes is not scored.
    m.on_pose(&pose(9, 100.0, 100.0, 0.0, cov));
    assert_relative_eq!(m.localization_rmse().unwrap(), 0.5, epsilon = 1e-12);
    assert_relative_eq!(m.mean_nees().unwrap(), 3.0, epsilon = 1e-9);
    let s = m.summary(&RunMeta::default());
    assert_eq!((s.pose_samples, s.nees_samples), (5, 4));
}

#[test]
fn nees_uses_the_full_covariance() {
    // Σ = [[2,1,0],[1,2,0],[0,0,1]]: Σ⁻¹ on the xy block is [[2,−1],[−1,2]]/3.
    let cov = [2.0, 1.0, 0.0, 1.0, 2.0, 0.0, 0.0, 0.0, 1.0];
    assert_relative_eq!(
        nees(&[1.0, 0.0, 0.0], &cov).unwrap(),
        2.0 / 3.0,
        epsilon = 1e-12
    );
    assert_relative_eq!(
        nees(&[1.0, 1.0, 2.0], &cov).unwrap(),
        2.0 / 3.0 + 4.0,
        epsilon = 1e-12
    );
    // Not positive definite.
    let bad = [1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    assert_eq!(nees(&[1.0, 0.0, 0.0], &bad), None);
    assert_eq!(nees(&[1.0, 0.0, 0.0], &[f64::NAN; 9]), None);
}

// ---------------------------------------------------------------------------------------------
// Truth: path, latency, goal, contacts
// ---------------------------------------------------------------------------------------------

#[test]
fn path_length_of_a_square_trajectory() {
    let mut m = Monitor::new(&walled_world(0.1)).unwrap();
    let corners = [(0.5, 0.5), (1.5, 0.5), (1.5, 1.5), (0.5, 1.5), (0.5, 0.5)];
    let mut tick = 0;
    for leg in corners.windows(2) {
        let ((x0, y0), (x1, y1)) = (leg[0], leg[1]);
        for k in 0..10 {
            let s = k as f64 / 10.0;
            m.on_truth(&truth(tick, x0 + s * (x1 - x0), y0 + s * (y1 - y0), 0.0));
            tick += 1;
        }
    }
    m.on_truth(&truth(tick, 0.5, 0.5, 0.0));
    // The same tick again adds nothing.
    m.on_truth(&truth(tick, 0.9, 0.5, 0.0));
    assert_relative_eq!(m.path_length(), 4.0, epsilon = 1e-9);
    assert_eq!(m.true_points().count(), 42);
}

#[test]
fn loop_latency_percentiles() {
    let mut m = Monitor::new(&walled_world(0.1)).unwrap();
    assert_eq!(m.loop_latency_us(0.5), None);
    for k in 1..=100u64 {
        let mut t = truth(k, 0.5, 1.0, 0.0);
        t.cmd_latency_ns = k * 1000;
        m.on_truth(&t);
        // Steps without a command carry 0 and are not counted.
        m.on_truth(&truth(k, 0.5, 1.0, 0.0));
    }
    let s = m.summary(&RunMeta::default());
    let lat = s.loop_latency_us;
    assert_relative_eq!(lat.p50.unwrap(), 50.0, max_relative = 1e-3);
    assert_relative_eq!(lat.p99.unwrap(), 99.0, max_relative = 1e-3);
    assert_relative_eq!(lat.max.unwrap(), 100.0, max_relative = 1e-3);
    let mut status: RunStatus = bytemuck::Zeroable::zeroed();
    status.header.seq = 42;
    m.write_status(&mut status);
    assert_eq!(status.header.seq, 42, "the header is the caller's");
    assert_relative_eq!(status.loop_p99_us, 99.0, max_relative = 1e-3);
    assert!(status.validate().is_ok());
}

#[test]
fn goal_contacts_penetration_and_end() {
    let mut m = Monitor::new(&walled_world(0.1)).unwrap();
    for tick in 1..=10u64 {
        let mut t = truth(tick, 0.5, 1.0, 0.0);
        if (3..=4).contains(&tick) || tick == 8 {
            t.flags |= TRUTH_IN_CONTACT;
            t.penetration = tick as f64 * 1e-3;
        }
        if tick >= 7 {
            t.flags |= TRUTH_GOAL_REACHED;
        }
        if tick == 10 {
            t.flags |= TRUTH_END;
            t.end_reason = mole_types::EndReason::GoalReached.code();
        }
        m.on_truth(&t);
    }
    assert!(m.ended());
    let s = m.summary(&RunMeta::default());
    assert!(s.goal_reached);
    assert_relative_eq!(s.time_to_goal_s.unwrap(), 0.07, epsilon = 1e-12);
    assert_eq!((s.contact_events, s.contact_ticks), (2, 3));
    assert_relative_eq!(s.max_penetration_m, 0.008);
    assert_eq!(s.ticks, 10);
    assert_relative_eq!(s.sim_time_s, 0.1, epsilon = 1e-12);
    assert_eq!(s.end_reason.as_deref(), Some("goal_reached"));
}

/// The world ends the run on the planner's MODE_DONE; the status with the flag may come after
/// the final truth, or never: the run still ended by the planner's word.
#[test]
fn an_exploration_complete_end_counts_as_ended_by_itself_without_the_status_flag() {
    let mut m = Monitor::new(&walled_world(0.1)).unwrap();
    let mut t = truth(1, 0.5, 1.0, 0.0);
    m.on_truth(&t);
    assert!(!m.summary(&RunMeta::default()).exploration_complete);
    t = truth(2, 0.5, 1.0, 0.0);
    t.flags |= TRUTH_END;
    t.end_reason = mole_types::EndReason::ExplorationComplete.code();
    m.on_truth(&t);
    let s = m.summary(&RunMeta::default());
    assert!(s.exploration_complete);
    assert_eq!(s.end_reason.as_deref(), Some("exploration_complete"));
}

// ---------------------------------------------------------------------------------------------
// Statistics and planner status
// ---------------------------------------------------------------------------------------------

fn stats(process: &str, pid: u32, topics: &[(&str, u32, f32, u64, u64)]) -> Stats {
    let mut s: Stats = bytemuck::Zeroable::zeroed();
    write_name(&mut s.process, process);
    s.pid = pid;
    s.n_topics = topics.len() as u32;
    for (slot, (name, dir, rate, dropped, invalid)) in s.topics.iter_mut().zip(topics) {
        write_name(&mut slot.topic, name);
        slot.direction = *dir;
        slot.rate_hz = *rate;
        slot.dropped = *dropped;
        slot.invalid = *invalid;
    }
    s
}

#[test]
fn topic_summary_takes_max_subscriber_rate_and_sums_drops() {
    let mut m = Monitor::new(&walled_world(0.1)).unwrap();
    const SUB: u32 = DIRECTION_SUBSCRIBE;
    const PUB: u32 = DIRECTION_PUBLISH;
    m.on_stats(&stats(
        "sensing",
        10,
        &[
            ("sensing/scan", PUB, 100.0, 1, 0),
            ("planning/cmd", SUB, 99.0, 0, 0),
        ],
    ));
    // An older report of the same process is replaced, not added.
    m.on_stats(&stats("mapping", 11, &[("sensing/scan", SUB, 40.0, 1, 0)]));
    m.on_stats(&stats("mapping", 11, &[("sensing/scan", SUB, 50.0, 2, 1)]));
    m.on_stats(&stats(
        "localization",
        12,
        &[("sensing/scan", SUB, 60.0, 3, 0)],
    ));
    // A restarted process (new pid) adds to its predecessor's counts.
    m.on_stats(&stats("mapping", 13, &[("sensing/scan", SUB, 45.0, 4, 2)]));
    m.on_stats(&stats(
        "planning",
        14,
        &[("planning/status", PUB, 10.0, 0, 0)],
    ));
    let topics = m.summary(&RunMeta::default()).topics;
    let scan = topics["sensing/scan"];
    assert_eq!(scan.rate_hz, 60.0);
    assert_eq!((scan.dropped, scan.invalid), (1 + 2 + 3 + 4, 1 + 2));
    assert_eq!(topics["planning/cmd"].rate_hz, 99.0);
    assert_eq!(
        topics["planning/status"].rate_hz, 10.0,
        "publisher rate when no subscriber"
    );
    assert_eq!(topics.len(), 3);
}

#[test]
fn plan_status_bounces_give_ups_and_exploration_flag() {
    let mut m = Monitor::new(&walled_world(0.1)).unwrap();
    let mut s: Box<PlanStatus> = bytemuck::zeroed_box();
    s.bounces = 3;
    s.give_ups = 1;
    s.mode = mole_types::MODE_EXPLORE;
    s.n_path = 2;
    s.path[1] = [1.0, 1.0];
    m.on_plan_status(&s);
    s.flags = STATUS_EXPLORATION_COMPLETE;
    s.bounces = 5;
    s.give_ups = 2;
    m.on_plan_status(&s);
    let sum = m.summary(&RunMeta::default());
    assert_eq!((sum.bounces, sum.give_ups), (5, 2));
    assert!(sum.exploration_complete);
    assert_eq!(m.plan_points().len(), 2);
    assert_eq!(m.plan_mode(), mole_types::MODE_EXPLORE);
}

// ---------------------------------------------------------------------------------------------
// Summary
// ---------------------------------------------------------------------------------------------

fn busy_monitor() -> Monitor {
    let mut m = Monitor::new(&walled_world(0.1)).unwrap();
    for tick in 0..50u64 {
        let x = 0.5 + 0.02 * tick as f64;
        let mut t = truth(tick, x, 1.0, 0.1);
        t.cmd_latency_ns = 20_000 + tick * 100;
        m.on_truth(&t);
        let mut p = pose(tick, x + 0.05, 1.02, 0.12, [0.01, 0.01, 0.01]);
        p.update_ns = 3_000;
        m.on_pose(&p);
    }
    m.on_grid(&grid(GRID_FRONTIER, 16, 8, 0.25, |col, row| {
        match (col, row) {
            (7..=8, 3..=4) => 2,
            (0..=6, _) => 1,
            _ => 0,
        }
    }));
    m.on_contact(&grid(GRID_CONTACT, 16, 8, 0.25, |col, row| {
        u8::from((col, row) == (6, 3))
    }));
    m.on_stats(&stats(
        "mapping",
        3,
        &[("sensing/scan", DIRECTION_SUBSCRIBE, 100.0, 0, 0)],
    ));
    let mut particles: Box<Particles> = bytemuck::zeroed_box();
    particles.n_particles = 100;
    // A filter larger than the message: the message carries a strided subset.
    particles.n_filter = 25_000;
    for (i, q) in particles.particles.iter_mut().take(100).enumerate() {
        q.x = 1.0 + 0.005 * i as f32;
        q.y = 1.5;
        q.w = 0.01;
    }
    m.on_particles(&particles);
    m
}

fn meta() -> RunMeta {
    RunMeta {
        planner: "frontier".into(),
        estimator: "ekf".into(),
        mode: "lockstep".into(),
        seed: 7,
        wall_time_s: 1.25,
        exit_reason: "ticks".into(),
        restarts: [("mapping".to_owned(), 1)].into_iter().collect(),
    }
}

#[test]
fn summary_json_has_every_field_with_its_type_and_round_trips() {
    let m = busy_monitor();
    let summary = m.summary(&meta());
    let text = serde_json::to_string_pretty(&summary).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let o = v.as_object().unwrap();
    for key in [
        "ticks",
        "seed",
        "reachable_free_cells",
        "contact_events",
        "pose_samples",
    ] {
        assert!(o[key].is_u64(), "{key}");
    }
    for key in [
        "sim_time_s",
        "wall_time_s",
        "time_to_goal_s",
        "path_length_m",
        "coverage",
        "contact_map_precision",
        "map_iou",
        "localization_rmse_m",
        "max_penetration_m",
        "mean_nees",
    ] {
        assert!(
            o[key].is_f64() || o[key].is_null() || o[key].is_u64(),
            "{key}"
        );
    }
    assert!(o["time_to_goal_s"].is_null(), "no goal reached");
    assert_eq!(o["coverage"].as_f64(), Some(56.0 / 84.0));
    assert_eq!(o["contact_map_precision"].as_f64(), Some(1.0));
    assert_eq!(o["map_iou"].as_f64(), Some(1.0));
    for key in [
        "planner",
        "estimator",
        "mode",
        "exit_reason",
        "grid_hash",
        "contact_hash",
    ] {
        assert!(o[key].is_string(), "{key}");
    }
    assert_eq!(o["grid_hash"].as_str().unwrap().len(), 16);
    assert!(o["goal_reached"].is_boolean());
    for q in ["p50", "p99", "max"] {
        assert!(o["loop_latency_us"][q].is_f64(), "{q}");
    }
    for q in ["p50", "p99"] {
        assert!(o["estimator_update_us"][q].is_f64(), "{q}");
    }
    assert_relative_eq!(
        o["estimator_update_us"]["p50"].as_f64().unwrap(),
        3.0,
        max_relative = 1e-3
    );
    let scan = &o["topics"]["sensing/scan"];
    assert!(scan["rate_hz"].is_f64() && scan["dropped"].is_u64() && scan["invalid"].is_u64());
    assert_eq!(o["restarts"]["mapping"].as_u64(), Some(1));
    assert!(o["bounces"].is_u64() && o["give_ups"].is_u64());
    // The particle set's size over the run, from the filter's count (not the message's).
    let p = &o["particles"];
    assert_eq!(
        (p["min"].as_u64(), p["max"].as_u64(), p["last"].as_u64()),
        (Some(25_000), Some(25_000), Some(25_000))
    );
    assert_eq!(p["series"], serde_json::json!([[0, 25_000]]));
    // The design's fields come first, in the design's order.
    let order = [
        "ticks",
        "sim_time_s",
        "wall_time_s",
        "planner",
        "estimator",
        "mode",
        "seed",
        "goal_reached",
        "time_to_goal_s",
        "path_length_m",
        "coverage",
        "contact_map_precision",
        "map_iou",
        "localization_rmse_m",
        "max_penetration_m",
        "loop_latency_us",
        "topics",
        "restarts",
        "exit_reason",
        "mean_nees",
        "estimator_update_us",
        "bounces",
        "give_ups",
        "grid_hash",
        "contact_hash",
        "reachable_free_cells",
    ];
    let positions: Vec<usize> = order
        .iter()
        .map(|k| {
            text.find(&format!("\n  \"{k}\":"))
                .unwrap_or_else(|| panic!("{k} missing"))
        })
        .collect();
    assert!(positions.windows(2).all(|w| w[0] < w[1]), "field order");
    let back: Summary = serde_json::from_str(&text).unwrap();
    assert_eq!(back, summary);

    let path = temp_path("summary.json");
    write_summary(&summary, &path).unwrap();
    let read: Summary = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    assert_eq!(read, summary);
    let _ = std::fs::remove_file(&path);
}

#[test]
fn empty_summary_serialises_unknowns_as_null() {
    let m = Monitor::new(&walled_world(0.1)).unwrap();
    let v = serde_json::to_value(m.summary(&meta())).unwrap();
    for key in [
        "contact_map_precision",
        "map_iou",
        "localization_rmse_m",
        "mean_nees",
        "grid_hash",
    ] {
        assert!(v[key].is_null(), "{key}");
    }
    assert!(v["loop_latency_us"]["p50"].is_null());
    assert_eq!(v["coverage"].as_f64(), Some(0.0));
}

#[test]
fn grid_hash_is_fnv1a_of_the_cells() {
    let m = busy_monitor();
    let s = m.summary(&meta());
    let expected = format!("{:016x}", fnv1a64(&m.grid.cells));
    assert_eq!(s.grid_hash.as_deref(), Some(expected.as_str()));
    assert_ne!(s.grid_hash, s.contact_hash);
}

// ---------------------------------------------------------------------------------------------
// Picture
// ---------------------------------------------------------------------------------------------

fn temp_path(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("mole-monitor-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(format!("{:?}-{name}", std::thread::current().id()).replace(['(', ')'], ""))
}

#[test]
fn render_png_writes_a_decodable_picture_with_the_legend_colours() {
    let mut m = busy_monitor();
    let mut s: Box<PlanStatus> = bytemuck::zeroed_box();
    s.n_path = 2;
    s.path[0] = [0.5, 1.0];
    s.path[1] = [1.5, 0.3];
    m.on_plan_status(&s);
    let path = temp_path("map.png");
    m.render_png(&path).unwrap();

    let file = std::io::BufReader::new(std::fs::File::open(&path).unwrap());
    let mut reader = png::Decoder::new(file).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let _ = std::fs::remove_file(&path);
    assert_eq!((info.width, info.height), m.image_size());
    assert!(info.width >= 800);
    assert_eq!(info.color_type, png::ColorType::Rgb);
    let px = |x: u32, y: u32| {
        let i = 3 * (y * info.width + x) as usize;
        [buf[i], buf[i + 1], buf[i + 2]]
    };
    let pixels: std::collections::HashSet<[u8; 3]> = buf[..info.buffer_size()]
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    for (colour, label) in render::LEGEND {
        assert!(pixels.contains(&colour), "{label} missing");
    }
    // Map: 4 × 2 m at 200 px/m from (20, 20), y up. The block cell (7,3) is black inside,
    // the unexplored right part dark grey, the start (0.5, 1.0) cyan.
    let to_px = |x: f64, y: f64| ((20.0 + x * 200.0) as u32, (20.0 + 400.0 - y * 200.0) as u32);
    let (x, y) = to_px(1.875, 0.875);
    assert_eq!(px(x, y), render::OCCUPIED);
    let (x, y) = to_px(3.6, 0.2);
    assert_eq!(px(x, y), render::UNEXPLORED);
    let (x, y) = to_px(0.5, 1.0);
    assert_eq!(px(x, y), render::START);
    let (x, y) = to_px(0.3, 0.2);
    assert_eq!(px(x, y), render::FREE);
    let (x, y) = to_px(1.625, 0.875);
    assert_eq!(px(x, y), render::CONTACT);
}

#[test]
fn render_survives_wild_coordinates_and_no_data() {
    let mut map = walled_world(0.1);
    map.n_obstacles += 1;
    map.obstacles[5] = Square::new(1e300, -1e300, 1e200);
    let mut m = Monitor::new(&map).unwrap();
    m.on_truth(&truth(1, 1e12, -1e12, 0.0));
    m.on_truth(&truth(2, f64::NAN, f64::INFINITY, 0.0));
    m.on_pose(&pose(2, -1e30, 0.0, 0.0, [1.0; 3]));
    let path = temp_path("wild.png");
    m.render_png(&path).unwrap();
    let _ = std::fs::remove_file(&path);
    assert!(m.render_png(Path::new("/nonexistent-dir/map.png")).is_err());
}

// ---------------------------------------------------------------------------------------------
// Robustness
// ---------------------------------------------------------------------------------------------

#[test]
fn grids_of_the_wrong_size_kind_resolution_or_origin_are_ignored_and_counted() {
    let mut m = Monitor::new(&walled_world(0.1)).unwrap();
    m.on_grid(&grid(GRID_FRONTIER, 16, 8, 0.25, |_, _| 1));
    assert_eq!(m.coverage(), 1.0);
    m.on_grid(&grid(GRID_FRONTIER, 8, 8, 0.25, |_, _| 0));
    m.on_grid(&grid(GRID_CONTACT, 16, 8, 0.25, |_, _| 0));
    m.on_grid(&grid(GRID_FRONTIER, 16, 8, 0.5, |_, _| 0));
    let mut shifted = grid(GRID_FRONTIER, 16, 8, 0.25, |_, _| 0);
    shifted.origin_x = -0.25;
    m.on_grid(&shifted);
    m.on_contact(&grid(GRID_CONTACT, 512, 512, 0.25, |_, _| 1));
    let mut huge = grid(GRID_FRONTIER, 16, 8, 0.25, |_, _| 0);
    huge.width = u32::MAX;
    m.on_grid(&huge);
    assert_eq!(m.coverage(), 1.0, "the good grid stands");
    assert_eq!(m.ignored_messages(), 6);
    assert_eq!(m.contact_map_precision(), None);
}

#[test]
fn a_grid_one_cell_larger_is_accepted_on_the_overlap() {
    // Mapping may round W/res up by one where the monitor forgives float noise.
    let mut m = Monitor::new(&walled_world(0.1)).unwrap();
    m.on_grid(&grid(GRID_FRONTIER, 17, 9, 0.25, |col, _| {
        u8::from(col <= 4)
    }));
    assert_eq!(m.ignored_messages(), 0);
    assert_eq!(m.coverage(), 40.0 / 84.0);
}

#[test]
fn stats_beyond_capacity_are_counted_not_stored() {
    let mut m = Monitor::new(&walled_world(0.1)).unwrap();
    for pid in 0..(MAX_PROCESSES as u32 + 5) {
        m.on_stats(&stats("p", pid, &[("x/y", DIRECTION_SUBSCRIBE, 1.0, 1, 0)]));
    }
    assert_eq!(m.ignored_messages(), 5);
    assert_eq!(
        m.summary(&meta()).topics["x/y"].dropped,
        MAX_PROCESSES as u64
    );
}

#[test]
fn per_message_methods_do_not_allocate_in_steady_state() {
    let mut m = busy_monitor();
    let g = grid(GRID_FRONTIER, 16, 8, 0.25, |col, _| u8::from(col < 5));
    let c = grid(GRID_CONTACT, 16, 8, 0.25, |col, _| u8::from(col == 6));
    let mut particles: Box<Particles> = bytemuck::zeroed_box();
    particles.n_particles = mole_types::MAX_PARTICLES as u32;
    particles.n_filter = particles.n_particles;
    let mut plan: Box<PlanStatus> = bytemuck::zeroed_box();
    plan.n_path = mole_types::MAX_PATH as u32;
    let mut landmarks: Box<Landmarks> = bytemuck::zeroed_box();
    landmarks.n_landmarks = mole_types::MAX_LANDMARKS as u32;
    let mut path: Box<Trajectory> = bytemuck::zeroed_box();
    path.first_tick = 40;
    path.n_poses = mole_types::MAX_TRAJECTORY_POSES as u32;
    for (i, p) in path.poses.iter_mut().enumerate() {
        p.tick_offset = i as u32;
    }
    let st = stats(
        "mapping",
        3,
        &[("sensing/scan", DIRECTION_SUBSCRIBE, 100.0, 0, 0)],
    );
    let new_process = stats(
        "world",
        99,
        &[("world/truth", DIRECTION_PUBLISH, 100.0, 0, 0)],
    );
    let mut status: RunStatus = bytemuck::Zeroable::zeroed();
    // The counter does see allocations on this thread.
    let probe = allocations();
    drop(std::hint::black_box(Vec::<u8>::with_capacity(8)));
    assert_eq!(allocations() - probe, 1);
    let before = allocations();
    for tick in 50..60_000u64 {
        let mut t = truth(tick, (tick % 300) as f64 * 0.01, 1.0, 0.0);
        t.cmd_latency_ns = 10_000 + tick;
        m.on_truth(&t);
        m.on_pose(&pose(tick, 1.0, 1.0, 0.0, [0.1; 3]));
        if tick % 100 == 0 {
            m.on_grid(&g);
            m.on_contact(&c);
            m.on_particles(&particles);
            m.on_plan_status(&plan);
            m.on_landmarks(&landmarks);
            m.on_trajectory(&path);
            m.on_stats(&st);
            m.on_stats(&new_process);
            m.write_status(&mut status);
            let _ = (
                m.coverage(),
                m.map_iou(),
                m.contact_map_precision(),
                m.localization_rmse(),
            );
        }
    }
    assert_eq!(allocations() - before, 0);
    assert!(m.true_track.len() <= MAX_TRACK_POINTS);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// Any truth and pose content leaves the metrics in range and the summary serialisable.
    #[test]
    fn arbitrary_messages_never_break_the_metrics(
        values in proptest::collection::vec(
            prop_oneof![any::<f64>(), -10.0..10.0f64, Just(f64::NAN), Just(f64::INFINITY)],
            12,
        ),
        ticks in proptest::collection::vec(0u64..400, 4),
        cells in proptest::collection::vec(0u8..=2, 128),
        flags in 0u32..8,
    ) {
        let mut m = Monitor::new(&walled_world(0.1)).unwrap();
        for (k, tick) in ticks.iter().enumerate() {
            let mut t = truth(*tick, values[k], values[k + 1], values[k + 2]);
            t.penetration = values[k + 3];
            t.flags = flags;
            t.end_reason = 9;
            t.n_contacts = 200;
            m.on_truth(&t);
            let mut p = pose(*tick, values[k + 4], values[k + 5], values[k + 6], [values[k + 7], 1.0, values[k + 8]]);
            p.covariance[1] = values[k + 7];
            m.on_pose(&p);
        }
        m.on_grid(&grid(GRID_FRONTIER, 16, 8, 0.25, |col, row| cells[row * 16 + col]));
        m.on_contact(&grid(GRID_CONTACT, 16, 8, 0.25, |col, row| cells[row * 16 + col] % 2));
        prop_assert!((0.0..=1.0).contains(&m.coverage()));
        for v in [m.map_iou(), m.contact_map_precision()].into_iter().flatten() {
            prop_assert!((0.0..=1.0).contains(&v));
        }
        let s = m.summary(&meta());
        let text = serde_json::to_string(&s).unwrap();
        let back: Summary = serde_json::from_str(&text).unwrap();
        prop_assert_eq!(back.ticks, s.ticks);
    }
}

#[test]
fn max_grid_cells_worlds_build_quickly() {
    // The largest grid a message holds: 512 × 512 cells with a few obstacles.
    let squares: Vec<Square> = (0..100)
        .map(|i| {
            Square::new(
                1.0 + (i % 10) as f64 * 2.4,
                1.0 + (i / 10) as f64 * 2.4,
                0.5,
            )
        })
        .collect();
    let mut map = world(25.6, 25.6, 0.05, 0.2, &squares);
    map.start_x = 2.2;
    map.start_y = 2.2;
    let m = Monitor::new(&map).unwrap();
    assert_eq!(m.grid_size(), (512, 512));
    assert_eq!(m.raster.flags.len(), MAX_GRID_CELLS);
    // Everything but the squares' clearance zones and the edge band is reachable.
    let free = m.raster.flags.iter().filter(|f| *f & OCCUPIED == 0).count() as u64;
    assert!(m.reachable_free_cells() > free * 8 / 10 && m.reachable_free_cells() < free);
}

// ---------------------------------------------------------------------------------------------
// SLAM: the landmark map against the true beacons
// ---------------------------------------------------------------------------------------------

/// The walled world with three beacons: b0 (1, 1), b1 (3, 1), b2 (2, 1.8).
fn beacon_world() -> Box<WorldMap> {
    let mut map = walled_world(0.1);
    map.place_beacons(&[(1.0, 1.0), (3.0, 1.0), (2.0, 1.8)]);
    map
}

/// A landmark map of `estimator` at `tick`: (id, x, y, diagonal of Σ) per landmark.
fn landmark_map(
    tick: u64,
    estimator: EstimatorKind,
    items: &[(u32, f64, f64, [f64; 2])],
) -> Box<Landmarks> {
    let mut map: Box<Landmarks> = bytemuck::zeroed_box();
    map.header.tick = tick;
    map.estimator = estimator.code();
    map.n_landmarks = items.len() as u32;
    for (slot, &(id, x, y, [sxx, syy])) in map.landmarks.iter_mut().zip(items) {
        *slot = mole_types::Landmark {
            id,
            _pad: 0,
            x,
            y,
            covariance: [sxx, 0.0, 0.0, syy],
        };
    }
    map
}

/// χ²₂ 0.95 is −2 ln 0.05, the 2-D 95% radius the ellipses are drawn at.
#[test]
fn chi2_two_dof_95_quantile_is_minus_two_ln_005() {
    assert_relative_eq!(CHI2_2_95, -2.0 * 0.05f64.ln(), max_relative = 1e-15);
    assert_relative_eq!(CHI2_2_95, 5.991, epsilon = 5e-4);
}

/// The 95% ellipse's semi-axes are √(5.991·λ) along Σ's eigenvectors, for a diagonal and a
/// rotated covariance; an indefinite or non-finite Σ has none.
#[test]
fn confidence_ellipse_axes_from_a_known_covariance() {
    let e = slam::confidence_ellipse(&[4.0, 0.0, 0.0, 1.0]).unwrap();
    assert_relative_eq!(e.major, 2.0 * CHI2_2_95.sqrt(), max_relative = 1e-12);
    assert_relative_eq!(e.minor, CHI2_2_95.sqrt(), max_relative = 1e-12);
    assert_relative_eq!(e.angle, 0.0);
    // R(45°) diag(4, 1) Rᵀ = [[2.5, 1.5], [1.5, 2.5]].
    let e = slam::confidence_ellipse(&[2.5, 1.5, 1.5, 2.5]).unwrap();
    assert_relative_eq!(e.major, 2.0 * CHI2_2_95.sqrt(), max_relative = 1e-12);
    assert_relative_eq!(e.minor, CHI2_2_95.sqrt(), max_relative = 1e-12);
    assert_relative_eq!(e.angle, PI / 4.0, max_relative = 1e-12);
    // Taller than wide: the major axis is vertical.
    let e = slam::confidence_ellipse(&[1.0, 0.0, 0.0, 9.0]).unwrap();
    assert_relative_eq!(e.major, 3.0 * CHI2_2_95.sqrt(), max_relative = 1e-12);
    assert_relative_eq!(e.angle.abs(), PI / 2.0, max_relative = 1e-12);
    assert_eq!(
        slam::confidence_ellipse(&[1.0, 2.0, 2.0, 1.0]),
        None,
        "eigenvalue −1"
    );
    assert_eq!(slam::confidence_ellipse(&[f64::NAN, 0.0, 0.0, 1.0]), None);
}

/// Landmark RMSE, NEES and association errors of a hand-made map, worked out by hand: two
/// landmarks by id, one anonymous matched to its nearest beacon, one anonymous matched to a beacon
/// already claimed (an association error), one naming a beacon the world lacks (another).
#[test]
fn slam_section_scores_a_hand_made_map() {
    let mut m = Monitor::new(&beacon_world()).unwrap();
    m.on_landmarks(&landmark_map(
        40,
        EstimatorKind::EkfSlam,
        &[
            (0, 1.1, 1.0, [0.01, 0.01]),                  // e = (0.1, 0), NEES 1
            (1, 3.0, 1.2, [0.01, 0.01]),                  // e = (0, 0.2), NEES 4
            (LANDMARK_ANONYMOUS, 2.0, 1.5, [0.09, 0.09]), // nearest b2, e = (0, −0.3), NEES 1
            (LANDMARK_ANONYMOUS, 1.0, 1.4, [0.0, 0.0]),   // nearest b0, taken; Σ not PD
            (7, 0.5, 0.5, [0.01, 0.01]),                  // no beacon 7
        ],
    ));
    let s = m.summary(&meta()).slam.expect("a landmark map arrived");
    assert_eq!(s.tick, Some(40));
    assert_eq!((s.landmarks, s.true_beacons, s.beacons_mapped), (5, 3, 3));
    assert_eq!((s.anonymous_landmarks, s.association_errors), (2, 2));
    assert_relative_eq!(s.association_error_rate.unwrap(), 2.0 / 5.0);
    // (0.1² + 0.2² + 0.3² + 0.4²) / 4 = 0.075.
    assert_relative_eq!(
        s.landmark_rmse_m.unwrap(),
        0.075f64.sqrt(),
        max_relative = 1e-12
    );
    assert_eq!(s.landmark_nees_samples, 3);
    assert_relative_eq!(s.landmark_nees.unwrap(), 2.0, max_relative = 1e-12);
    // χ²₆(0.025) = 1.2373 and χ²₆(0.975) = 14.4494 (tables), over n = 3.
    let [lo, hi] = s.landmark_nees_interval.unwrap();
    assert_relative_eq!(lo, 1.2373 / 3.0, max_relative = 1e-4);
    assert_relative_eq!(hi, 14.4494 / 3.0, max_relative = 1e-4);
}

/// The interval is drawn from the degrees of freedom the estimator publishes for its map's
/// mean NEES (its landmarks share an error): ν = 3 here, χ²₃(0.025) = 0.2158 and
/// χ²₃(0.975) = 9.3484 (tables), times 2/3; without it, from 2n as for independent landmarks.
#[test]
fn the_nees_interval_is_of_the_dof_the_estimator_publishes() {
    let items = [
        (0, 1.1, 1.0, [0.01, 0.01]),
        (1, 3.0, 1.2, [0.01, 0.01]),
        (2, 2.0, 1.8, [0.09, 0.09]),
    ];
    let mut m = Monitor::new(&beacon_world()).unwrap();
    let mut map = landmark_map(40, EstimatorKind::EkfSlam, &items);
    map.nees_dof = 3.0;
    m.on_landmarks(&map);
    let s = m.summary(&meta()).slam.expect("a landmark map arrived");
    assert_eq!(s.landmark_nees_dof, Some(3.0));
    let [lo, hi] = s.landmark_nees_interval.unwrap();
    assert_relative_eq!(lo, 2.0 * 0.2158 / 3.0, max_relative = 1e-3);
    assert_relative_eq!(hi, 2.0 * 9.3484 / 3.0, max_relative = 1e-4);
    // More than 2n cannot be: clamped to the independent landmarks' 2n = 6.
    map.nees_dof = 50.0;
    m.on_landmarks(&map);
    let s = m.summary(&meta()).slam.unwrap();
    assert_eq!(s.landmark_nees_dof, Some(6.0));
    assert_eq!(s.landmark_nees_interval, mean_nees_interval(2, 3));
}

/// A later map replaces the earlier one, and a full-covariance NEES uses the off-diagonal.
#[test]
fn slam_section_scores_the_latest_map_with_its_full_covariance() {
    let mut m = Monitor::new(&beacon_world()).unwrap();
    m.on_landmarks(&landmark_map(
        5,
        EstimatorKind::FastSlam,
        &[(0, 9.0, 9.0, [1.0, 1.0])],
    ));
    let mut map = landmark_map(6, EstimatorKind::FastSlam, &[(1, 3.1, 1.1, [2.0, 2.0])]);
    map.landmarks[0].covariance = [2.0, 1.0, 1.0, 2.0];
    m.on_landmarks(&map);
    let s = m.slam().unwrap();
    assert_eq!((s.tick, s.landmarks, s.association_errors), (Some(6), 1, 0));
    assert_relative_eq!(
        s.landmark_rmse_m.unwrap(),
        0.02f64.sqrt(),
        max_relative = 1e-12
    );
    // e = (0.1, 0.1), Σ⁻¹ = [[2, −1], [−1, 2]] / 3: eᵀΣ⁻¹e = 0.02 / 3.
    assert_relative_eq!(s.landmark_nees.unwrap(), 0.02 / 3.0, max_relative = 1e-12);
}

/// The section is null for an ordinary estimator and present, with nothing scored, for a SLAM
/// estimator whose map has not arrived.
#[test]
fn slam_section_is_null_without_a_slam_estimator() {
    let mut m = Monitor::new(&beacon_world()).unwrap();
    m.on_pose(&pose(1, 1.0, 1.0, 0.0, [0.1; 3]));
    assert_eq!(m.summary(&meta()).slam, None);
    let v = serde_json::to_value(m.summary(&meta())).unwrap();
    assert!(v["slam"].is_null());
    let mut p = pose(2, 1.0, 1.0, 0.0, [0.1; 3]);
    p.estimator = EstimatorKind::GraphSlam.code();
    m.on_pose(&p);
    let s = m.summary(&meta()).slam.expect("a SLAM estimator");
    assert_eq!((s.tick, s.landmarks, s.true_beacons), (None, 0, 3));
    assert_eq!(
        (s.landmark_rmse_m, s.landmark_nees, s.landmark_nees_interval),
        (None, None, None)
    );
}

/// map.png draws the true beacons and each landmark's 95% ellipse where they belong.
#[test]
fn render_png_draws_beacons_and_landmark_ellipses() {
    let mut m = Monitor::new(&beacon_world()).unwrap();
    // Σ = diag(0.25, 0.04) / 5.991: semi-axes 0.5 m along x and 0.2 m along y.
    let (sxx, syy) = (0.25 / CHI2_2_95, 0.04 / CHI2_2_95);
    m.on_landmarks(&landmark_map(
        3,
        EstimatorKind::EkfSlam,
        &[(1, 2.4, 1.0, [sxx, syy])],
    ));
    let path = temp_path("slam_map.png");
    m.render_png(&path).unwrap();
    let file = std::io::BufReader::new(std::fs::File::open(&path).unwrap());
    let mut reader = png::Decoder::new(file).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let _ = std::fs::remove_file(&path);
    // 4 × 2 m at 200 px/m from (20, 20), y up; the colour at a pixel and whether `colour` is
    // within a pixel of it (outlines are 2 px wide).
    let at = |c: i64, r: i64| {
        let i = 3 * (r as usize * info.width as usize + c as usize);
        [buf[i], buf[i + 1], buf[i + 2]]
    };
    let to_px = |x: f64, y: f64| ((20.0 + x * 200.0) as i64, (20.0 + 400.0 - y * 200.0) as i64);
    let px = |x: f64, y: f64| {
        let (c, r) = to_px(x, y);
        at(c, r)
    };
    let near = |x: f64, y: f64, colour: render::Rgb| {
        let (c, r) = to_px(x, y);
        (-1..=1).any(|dr| (-1..=1).any(|dc| at(c + dc, r + dr) == colour))
    };
    assert_eq!(px(1.0, 1.0), render::BEACON, "true beacon b0");
    assert_eq!(px(2.0, 1.8), render::BEACON, "true beacon b2");
    assert_eq!(px(2.4, 1.0), render::LANDMARK, "landmark mean");
    assert!(
        near(2.9, 1.0, render::LANDMARK),
        "ellipse end of the major axis"
    );
    assert!(
        near(2.4, 1.2, render::LANDMARK),
        "ellipse end of the minor axis"
    );
    assert!(
        near(2.4, 0.8, render::LANDMARK),
        "ellipse end of the minor axis"
    );
    assert!(!near(2.75, 1.0, render::LANDMARK), "inside the ellipse");
}

// ---------------------------------------------------------------------------------------------
// The smoothed trajectory against the truth and the filter
// ---------------------------------------------------------------------------------------------

/// A GraphSLAM trajectory published at `tick`: (tick offset, x, y) per pose from `first_tick`.
fn trajectory(tick: u64, first_tick: u64, poses: &[(u32, f64, f64)]) -> Box<Trajectory> {
    let mut path: Box<Trajectory> = bytemuck::zeroed_box();
    path.header.tick = tick;
    path.first_tick = first_tick;
    path.estimator = EstimatorKind::GraphSlam.code();
    path.n_poses = poses.len() as u32;
    for (slot, &(tick_offset, x, y)) in path.poses.iter_mut().zip(poses) {
        *slot = mole_types::TrajectoryPose {
            tick_offset,
            x: x as f32,
            y: y as f32,
            theta: 0.0,
        };
    }
    path
}

/// The smoothed RMSE and the filter's are taken over the same ticks, worked out by hand: those
/// of the trajectory with both a truth and a filter pose (not tick 4, whose pose is missing, nor
/// tick 50, never simulated), and no longer a tick the ring has let go.
#[test]
fn smoothed_and_filter_rmse_cover_the_same_ticks() {
    let mut m = Monitor::new(&beacon_world()).unwrap();
    let x = |tick: u64| 1.0 + 0.1 * tick as f64;
    for tick in 0..10 {
        m.on_truth(&truth(tick, x(tick), 1.0, 0.0));
        if tick != 4 {
            // The filter is 0.3 m off on even ticks, 0.1 m on odd ones.
            let dy = if tick % 2 == 0 { 0.3 } else { 0.1 };
            let mut p = pose(tick, x(tick), 1.0 + dy, 0.0, [0.1; 3]);
            p.estimator = EstimatorKind::GraphSlam.code();
            m.on_pose(&p);
        }
    }
    let s = m.slam().expect("a SLAM estimator");
    assert_eq!((s.smoothed_tick, s.smoothed_samples), (None, 0), "none yet");
    assert_eq!(
        (s.smoothed_rmse_m, s.filter_rmse_same_ticks_m),
        (None, None)
    );
    // Ticks 2..=8, 0.1 m off (0.2 m at tick 8), and tick 50.
    let mut poses: Vec<(u32, f64, f64)> = (2..=8u64)
        .map(|t| ((t - 2) as u32, x(t) + if t == 8 { 0.2 } else { 0.1 }, 1.0))
        .collect();
    poses.push((48, 0.0, 0.0));
    let path = trajectory(9, 2, &poses);
    m.on_trajectory(&path);
    let s = m.slam().unwrap();
    // Ticks 2, 3, 5, 6, 7, 8: smoothed 5 · 0.01 + 0.04, filter 3 · 0.09 + 3 · 0.01.
    assert_eq!((s.smoothed_tick, s.smoothed_samples), (Some(9), 6));
    assert_relative_eq!(
        s.smoothed_rmse_m.unwrap(),
        (0.09f64 / 6.0).sqrt(),
        max_relative = 1e-5
    );
    assert_relative_eq!(
        s.filter_rmse_same_ticks_m.unwrap(),
        (0.30f64 / 6.0).sqrt(),
        max_relative = 1e-5
    );
    // Tick 2's slot now holds a tick one ring later, truth and filter: the same trajectory
    // again scores 5 ticks.
    let later = 2 + smoothed::TICK_HISTORY as u64;
    m.on_truth(&truth(later, 1.0, 1.0, 0.0));
    let mut p = pose(later, 1.0, 1.0, 0.0, [0.1; 3]);
    p.estimator = EstimatorKind::GraphSlam.code();
    m.on_pose(&p);
    m.on_trajectory(&path);
    let s = m.slam().unwrap();
    assert_eq!(s.smoothed_samples, 5);
    assert_relative_eq!(
        s.smoothed_rmse_m.unwrap(),
        (0.08f64 / 5.0).sqrt(),
        max_relative = 1e-5
    );
    assert_relative_eq!(
        s.filter_rmse_same_ticks_m.unwrap(),
        (0.21f64 / 5.0).sqrt(),
        max_relative = 1e-5
    );
}

/// map.png draws the newest smoothed trajectory in its own colour.
#[test]
fn render_png_draws_the_smoothed_trajectory() {
    let mut m = Monitor::new(&beacon_world()).unwrap();
    m.on_trajectory(&trajectory(3, 0, &[(0, 0.5, 0.5), (1, 3.5, 0.5)]));
    let path = temp_path("smoothed_map.png");
    m.render_png(&path).unwrap();
    let file = std::io::BufReader::new(std::fs::File::open(&path).unwrap());
    let mut reader = png::Decoder::new(file).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let _ = std::fs::remove_file(&path);
    // 4 × 2 m at 200 px/m from (20, 20), y up: (2.0, 0.5) lies on the segment.
    let (c, r) = (20 + 2 * 200, 20 + 400 - 100);
    let i = 3 * (r * info.width as usize + c);
    assert_eq!([buf[i], buf[i + 1], buf[i + 2]], render::SMOOTHED_TRACK);
}
