//! Planner benchmarks: DWA command (20 × 20 window, 3 s horizon), frontier selection on a
//! 400 × 400 grid, APF force at a point with a distance field.

use criterion::{Criterion, criterion_group, criterion_main};
use mole_planning::apf::{Apf, ApfConfig};
use mole_planning::dwa::{Dwa, DwaConfig, DwaState, Sampling};
use mole_planning::frontier::{
    FrontierCells, FrontierConfig, FrontierSelector, frontier_cells_full,
};
use mole_planning::{DistanceField, Planner, RobotLimits};
use mole_types::{CELL_FREE, CELL_OCCUPIED, CELL_UNEXPLORED, Grid};
use std::hint::black_box;

fn limits() -> RobotLimits {
    RobotLimits::default()
}

/// A w × h grid at `res` with walls, scattered boxes, and the right third unexplored.
fn grid(w: usize, h: usize, res: f64) -> Box<Grid> {
    let mut g: Box<Grid> = bytemuck::zeroed_box();
    g.width = w as u32;
    g.height = h as u32;
    g.resolution = res;
    for r in 0..h {
        for c in 0..w {
            let border = r == 0 || c == 0 || r == h - 1 || c == w - 1;
            let boxed = (c / 20) % 3 == 1 && (r / 20) % 3 == 1 && c % 20 < 8 && r % 20 < 8;
            g.cells[r * w + c] = if border || boxed {
                CELL_OCCUPIED
            } else if c > 2 * w / 3 {
                CELL_UNEXPLORED
            } else {
                CELL_FREE
            };
        }
    }
    g
}

/// Scans of a robot driving along the frontier of [`grid`] (400 × 400): each reveals the
/// unexplored cells of a disc of 14 cells 8 cells further on, and walls a stretch of its rim;
/// a few hundred cells change per step.
fn scan_steps(base: &Grid, n: usize) -> Vec<Box<Grid>> {
    let (w, h) = (base.width as usize, base.height as usize);
    let mut g: Box<Grid> = bytemuck::zeroed_box();
    *g = *base;
    let mut steps = Vec::with_capacity(n);
    for k in 0..n {
        let (cc, cr) = (2 * w as i64 / 3 + 2, 30 + 8 * k as i64);
        for r in (cr - 14).max(1)..(cr + 15).min(h as i64 - 1) {
            for c in (cc - 14).max(1)..(cc + 15).min(w as i64 - 1) {
                let d2 = (r - cr) * (r - cr) + (c - cc) * (c - cc);
                let i = r as usize * w + c as usize;
                if d2 < 13 * 13 && g.cells[i] == CELL_UNEXPLORED {
                    g.cells[i] = CELL_FREE;
                } else if d2 < 14 * 14 && c > cc + 9 && g.cells[i] == CELL_UNEXPLORED {
                    g.cells[i] = CELL_OCCUPIED;
                }
            }
        }
        let mut s: Box<Grid> = bytemuck::zeroed_box();
        *s = *g;
        steps.push(s);
    }
    steps
}

/// The k-th grid of a back-and-forth walk over `n` grids: each step changes one scan.
fn ping_pong(k: usize, n: usize) -> usize {
    let p = k % (2 * n - 2);
    if p < n { p } else { 2 * n - 2 - p }
}

fn benches(c: &mut Criterion) {
    let g = grid(200, 200, 0.05);
    // A ring of wall 2 m around the robot, in the grid and in the scan (the mapping folds each
    // scan into the grid, so the scan's hits are known cells).
    let mut ringed = grid(200, 200, 0.05);
    for k in 0..3600 {
        let a = k as f64 * std::f64::consts::TAU / 3600.0;
        let (x, y) = (3.0 + 2.02 * a.cos(), 3.0 + 2.02 * a.sin());
        let i = (y / 0.05) as usize * 200 + (x / 0.05) as usize;
        ringed.cells[i] = CELL_OCCUPIED;
    }
    let mut scan: Box<mole_types::Scan> = bytemuck::zeroed_box();
    scan.n_beams = 360;
    scan.angle_min = -std::f32::consts::PI;
    scan.angle_increment = std::f32::consts::TAU / 360.0;
    scan.range_max = 4.0;
    for r in scan.ranges.iter_mut().take(360) {
        *r = 2.0;
    }
    let mut dwa = Dwa::new(
        limits(),
        DwaConfig {
            sampling: Sampling::Count { nv: 20, nw: 20 },
            predict_time: 3.0,
            ..Default::default()
        },
        [8.0, 8.0],
    );
    let input = mole_planning::PlannerInput {
        tick: 0,
        dt: 0.05,
        pose: mole_types::Pose2::new(3.0, 3.0, 0.5),
        scan: Some(&scan),
        tactile: None,
        grid: Some(&ringed),
        last_command: mole_planning::Command::STOP,
    };
    dwa.follow(&input);
    // The whole command: field check, scan folding, 400 rollouts of 3 s.
    c.bench_function("dwa_20x20_3s", |b| {
        b.iter(|| black_box(dwa.follow(black_box(&input))))
    });
    let s = DwaState {
        x: 3.0,
        y: 3.0,
        theta: 0.5,
        v: 0.3,
        omega: 0.0,
    };
    c.bench_function("dwa_choose_only_20x20_3s", |b| {
        b.iter(|| black_box(dwa.choose(black_box(&s))))
    });
    // The global path (every `replan_every` steps): A* over the inflated 200 × 200 grid.
    let mut gp = mole_planning::GlobalPath::new();
    let mut field = DistanceField::new();
    field.update(&g);
    c.bench_function("dwa_global_plan_200x200", |b| {
        b.iter(|| black_box(gp.plan(&g, &field, [1.0, 1.0], [6.5, 8.5], 0.32)))
    });

    let big = grid(400, 400, 0.05);
    let mut sel = FrontierSelector::new(FrontierConfig::default(), 0.2);
    sel.select(&big, [3.0, 3.0]);
    c.bench_function("frontier_select_400x400", |b| {
        b.iter(|| black_box(sel.select(black_box(&big), [3.0, 3.0])))
    });

    // Per step (Keidar & Kaminka 2014, fast frontier detection): the frontier set after one
    // scan, full pass against the changed cells only, and the whole selection each way.
    let steps = scan_steps(&big, 40);
    let n = steps.len();
    let changed: usize = (1..n)
        .map(|k| {
            let (a, b) = (steps[k - 1].cells(), steps[k].cells());
            a.iter().zip(b).filter(|(x, y)| x != y).count()
        })
        .sum();
    println!(
        "frontier step: {} cells changed per scan on average",
        changed / (n - 1)
    );
    let mut out = Vec::with_capacity(400 * 400);
    let mut k = 0;
    c.bench_function("frontier_cells_full_400x400_step", |b| {
        b.iter(|| {
            k += 1;
            let g = &steps[ping_pong(k, n)];
            frontier_cells_full(black_box(g.cells()), 400, 400, &mut out);
            black_box(out.len())
        })
    });
    let mut cells = FrontierCells::with_capacity(400 * 400);
    cells.update(steps[0].cells(), 400, 400);
    c.bench_function("frontier_cells_incremental_400x400_step", |b| {
        b.iter(|| {
            k += 1;
            let g = &steps[ping_pong(k, n)];
            cells.update(black_box(g.cells()), 400, 400);
            black_box(cells.len())
        })
    });
    let robot = [3.0, 3.0];
    for (name, full) in [
        ("frontier_select_full_pass_400x400_step", true),
        ("frontier_select_incremental_400x400_step", false),
    ] {
        let mut sel = FrontierSelector::new(FrontierConfig::default(), 0.2);
        sel.set_full_pass(full);
        sel.select(&steps[0], robot);
        c.bench_function(name, |b| {
            b.iter(|| {
                k += 1;
                black_box(sel.select(black_box(&steps[ping_pong(k, n)]), robot))
            })
        });
    }
    // The selection's other parts per step: the distance field (rebuilt: the scans wall cells),
    // the inflation and the Dijkstra search.
    let mut field400 = DistanceField::with_capacity(400 * 400);
    c.bench_function("frontier_part_field_update_400x400_step", |b| {
        b.iter(|| {
            k += 1;
            black_box(field400.update(black_box(&steps[ping_pong(k, n)])))
        })
    });
    let mut passable = Vec::with_capacity(400 * 400);
    c.bench_function("frontier_part_clear_of_400x400", |b| {
        b.iter(|| field400.clear_of(black_box(0.32), &mut passable))
    });
    for (p, c) in passable.iter_mut().zip(steps[n - 1].cells()) {
        *p &= *c == CELL_FREE;
    }
    let mut search = mole_planning::GridSearch::with_capacity(400 * 400);
    c.bench_function("frontier_part_dijkstra_400x400", |b| {
        b.iter(|| {
            let p = &passable;
            search.dijkstra(400, 400, &|i| p[i], 60 * 400 + 60);
            black_box(search.settled())
        })
    });

    c.bench_function("distance_field_build_200x200", |b| {
        b.iter(|| {
            let mask = g.cells();
            field.build_from_mask(200, 200, 0.05, [0.0, 0.0], black_box(mask));
        })
    });

    let mut apf = Apf::new(limits(), ApfConfig::default(), [8.0, 8.0], 1);
    apf.set_goal([8.0, 8.0], None);
    let mut st = mole_types::Pose2::new(3.0, 3.0, 0.0);
    // Feed the grid once so the field is built.
    let input = mole_planning::PlannerInput {
        tick: 0,
        dt: 0.05,
        pose: st,
        scan: None,
        tactile: None,
        grid: Some(&g),
        last_command: mole_planning::Command::STOP,
    };
    mole_planning::Planner::step(&mut apf, &input);
    c.bench_function("apf_force_at_point", |b| {
        b.iter(|| {
            st.x = (st.x + 0.013) % 9.0;
            black_box(apf.force(black_box([st.x + 0.5, 3.1]), None))
        })
    });
}

criterion_group!(planners, benches);
criterion_main!(planners);
