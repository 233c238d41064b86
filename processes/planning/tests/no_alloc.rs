//! Every planner's step allocates nothing in steady state (a counting global allocator).

use mole_planning::{Command, Planner, PlannerConfig, PlannerInput, RobotLimits, build_planner};
use mole_runtime::{CountingAllocator, allocations_during};
use mole_types::{CELL_FREE, CELL_OCCUPIED, CELL_UNEXPLORED, Grid, PlannerKind, Pose2, Scan};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

fn limits() -> RobotLimits {
    RobotLimits::default()
}

/// A 10 m × 10 m map at 0.05 m: walls, a box, the right half unexplored; a full-circle scan.
fn world() -> (Box<Grid>, Box<Scan>) {
    let mut g: Box<Grid> = bytemuck::zeroed_box();
    let (w, h) = (200usize, 200usize);
    g.width = w as u32;
    g.height = h as u32;
    g.resolution = 0.05;
    for r in 0..h {
        for c in 0..w {
            let border = r == 0 || c == 0 || r == h - 1 || c == w - 1;
            let boxed = (80..90).contains(&c) && (40..60).contains(&r);
            g.cells[r * w + c] = if border || boxed {
                CELL_OCCUPIED
            } else if c > 120 {
                CELL_UNEXPLORED
            } else {
                CELL_FREE
            };
        }
    }
    let mut s: Box<Scan> = bytemuck::zeroed_box();
    s.n_beams = 360;
    s.angle_min = -std::f32::consts::PI;
    s.angle_increment = std::f32::consts::TAU / 360.0;
    s.range_max = 4.0;
    for i in 0..360 {
        s.ranges[i] = 1.5 + (i % 7) as f32 * 0.3;
    }
    (g, s)
}

/// Every planner's step (and re-planning) allocates nothing once running.
#[test]
fn every_planner_step_allocates_nothing_in_steady_state() {
    // A broken counter would pass everything below: it must see this Box first.
    let boxed = allocations_during(|| {
        std::hint::black_box(Box::new([0u8; 64]));
    });
    assert!(boxed >= 1, "a Box was allocated, the counter saw {boxed}");
    let (grid, scan) = world();
    for (kind, local, replan) in [
        (PlannerKind::RandomWalk, PlannerKind::Dwa, false),
        (PlannerKind::Apf, PlannerKind::Dwa, false),
        (PlannerKind::Dwa, PlannerKind::Dwa, false),
        (PlannerKind::Frontier, PlannerKind::Dwa, false),
        (PlannerKind::Frontier, PlannerKind::Apf, false),
        // `dwa` re-planning with APF after a bounce (`local` names the re-planner here).
        (PlannerKind::Dwa, PlannerKind::Apf, true),
    ] {
        let mut cfg = PlannerConfig::new(kind);
        if replan {
            cfg.settings.replan_with = Some(local);
            cfg.settings.replan_time = 1.0;
        }
        cfg.goal = Some((8.0, 8.0));
        cfg.local = local;
        cfg.settings.frontier.reselect_every = 5; // select often, so selection runs inside the window
        let mut p = build_planner(&cfg, limits()).unwrap_or_else(|e| panic!("{e}"));
        let mut pose = Pose2::new(2.0, 2.0, 0.3);
        let mut status: Box<mole_types::PlanStatus> = bytemuck::zeroed_box();
        let mut last_command = Command::STOP;
        let mut step = |p: &mut Box<dyn Planner>, tick: u64, pose: &mut Pose2| {
            let input = PlannerInput {
                tick,
                dt: 0.05,
                pose: *pose,
                scan: Some(&scan),
                tactile: None,
                grid: Some(&grid),
                last_command,
            };
            let c = p.step(&input);
            last_command = c;
            p.write_status(&mut status);
            pose.x += c.v * pose.theta.cos() * 0.05;
            pose.y += c.v * pose.theta.sin() * 0.05;
            pose.theta += c.omega * 0.05;
        };
        for tick in 0..50 {
            step(&mut p, tick, &mut pose);
        }
        let n = allocations_during(|| {
            for tick in 50..150 {
                if replan && tick % 40 == 0 {
                    p.replan();
                }
                step(&mut p, tick, &mut pose);
            }
        });
        assert_eq!(n, 0, "{kind} ({local:?}) allocated {n} times in 100 steps");
    }
}
