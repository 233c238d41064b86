//! Closed loop: the random walk inside bounce-back drives a unicycle in a 5 m box whose walls are
//! the only obstacles, seen by a synthetic lidar (ray cast against the walls) and tactile rim
//! sensors (stiffness × penetration). With a lidar the robot must never touch a wall; blind, with
//! touch alone, every contact must turn the robot's motion away from the wall within the braking
//! time and it must not keep pushing into the wall. Either way it must keep moving and visit a
//! growing share of the box.

use mole_planning::{
    BounceBack, BounceBackConfig, Command, Limited, Planner, PlannerInput, RandomWalk,
    RandomWalkConfig, RobotLimits, planner_by_kind,
};
use mole_types::{MAX_BEAMS, PlannerKind, Pose2, Scan, Tactile, wrap_angle};
use std::f64::consts::{PI, TAU};

const SIDE: f64 = 5.0;
const DT: f64 = 0.05;
const RANGE_MAX: f64 = 4.0;
const BEAMS: usize = 180;
const STIFFNESS: f64 = 2000.0;
const CELL: f64 = 0.25;

/// The robot of the default scenario: 0.2 m disk, 0.5 m/s, 2 rad/s, 2 m/s², 8 rad/s².
fn limits() -> RobotLimits {
    RobotLimits::default()
}

/// Distance from (x, y) along heading `a` to the box wall.
fn ray(x: f64, y: f64, a: f64) -> f64 {
    let (s, c) = a.sin_cos();
    let mut t = f64::INFINITY;
    if c > 1e-12 {
        t = t.min((SIDE - x) / c);
    } else if c < -1e-12 {
        t = t.min(-x / c);
    }
    if s > 1e-12 {
        t = t.min((SIDE - y) / s);
    } else if s < -1e-12 {
        t = t.min(-y / s);
    }
    t.max(0.0)
}

/// A full-circle scan of the box from `pose`, noise-free.
fn cast(pose: &Pose2, scan: &mut Scan) {
    scan.n_beams = BEAMS as u32;
    scan.angle_min = -PI as f32;
    scan.angle_increment = (TAU / BEAMS as f64) as f32;
    scan.range_max = RANGE_MAX as f32;
    for i in 0..BEAMS {
        let a = pose.theta - PI + i as f64 * TAU / BEAMS as f64;
        scan.ranges[i] = ray(pose.x, pose.y, a).min(RANGE_MAX) as f32;
    }
    scan.ranges[BEAMS..MAX_BEAMS].fill(0.0);
}

/// Tactile forces from each wall the disk overlaps.
fn touch(pose: &Pose2, r: f64, tactile: &mut Tactile) {
    let k = 8;
    tactile.n_sensors = k as u32;
    tactile.radius = r as f32;
    for (i, s) in tactile.sensors[..k].iter_mut().enumerate() {
        *s = Default::default();
        s.angle = (TAU * i as f64 / k as f64) as f32;
    }
    // (distance to the wall, world direction of the wall from the centre)
    let walls = [
        (pose.x, PI),
        (SIDE - pose.x, 0.0),
        (pose.y, -PI / 2.0),
        (SIDE - pose.y, PI / 2.0),
    ];
    for (d, dir) in walls {
        let depth = r - d;
        if depth <= 0.0 {
            continue;
        }
        let rel = wrap_angle(dir - pose.theta);
        let f = STIFFNESS * depth; // pushes the robot away from the wall
        let i = ((rel.rem_euclid(TAU) / (TAU / k as f64)).round() as usize) % k;
        tactile.sensors[i].fx -= (f * rel.cos()) as f32;
        tactile.sensors[i].fy -= (f * rel.sin()) as f32;
    }
}

/// Outward normal of the contact: the sum of the normals of the walls the disk presses into
/// deeper than `felt` (m), pointing back into the box; `None` without such a contact.
fn contact_normal(pose: &Pose2, r: f64, felt: f64) -> Option<[f64; 2]> {
    let walls = [
        (pose.x, [1.0, 0.0]),
        (SIDE - pose.x, [-1.0, 0.0]),
        (pose.y, [0.0, 1.0]),
        (SIDE - pose.y, [0.0, -1.0]),
    ];
    let mut n: Option<[f64; 2]> = None;
    for (d, w) in walls {
        if r - d > felt {
            let s = n.get_or_insert([0.0, 0.0]);
            s[0] += w[0];
            s[1] += w[1];
        }
    }
    n
}

/// One contact, from the first step the rim sensors feel a wall to the first step they do not.
#[derive(Debug, Clone, Copy)]
struct Contact {
    /// Steps from the onset to the first command that drives away from the wall (or to the end
    /// of the contact if none did).
    steps_to_release: usize,
    /// Steps of the contact whose command drove further into the wall.
    pushing_steps: usize,
    /// Whether a command drove away from the wall during the contact.
    released: bool,
}

/// What one closed-loop run achieved.
struct Outcome {
    min_wall_distance: f64,
    min_window_excursion: f64,
    coverage: Vec<f64>,
    bounces: u32,
    contacts: Vec<Contact>,
}

/// Runs `steps` steps; with `lidar` false the scan has no beams and contacts are resolved (the
/// robot is pushed back out of the wall, as the world process does).
fn run(planner: &mut dyn Planner, steps: usize, lidar: bool) -> Outcome {
    let r = limits().radius;
    let mut scan: Box<Scan> = bytemuck::zeroed_box();
    let mut tactile: Box<Tactile> = bytemuck::zeroed_box();
    let mut pose = Pose2::new(1.0, 1.0, 0.3);
    let mut last = Command::STOP;
    let n_cells = (SIDE / CELL) as usize;
    let mut visited = vec![false; n_cells * n_cells];
    let mut out = Outcome {
        min_wall_distance: f64::INFINITY,
        min_window_excursion: f64::INFINITY,
        coverage: Vec::new(),
        bounces: 0,
        contacts: Vec::new(),
    };
    // The depth at which the rim force reaches the bounce-back's threshold.
    let felt = BounceBackConfig::default().force_threshold / STIFFNESS;
    let mut contact: Option<Contact> = None;
    let window = (10.0 / DT) as usize;
    let (mut window_start, mut excursion) = (pose, 0.0f64);
    for step in 0..steps {
        if lidar {
            cast(&pose, &mut scan);
        } else {
            scan.n_beams = 0;
        }
        touch(&pose, r, &mut tactile);
        let input = PlannerInput {
            tick: step as u64,
            dt: DT,
            pose,
            scan: Some(&scan),
            tactile: Some(&tactile),
            grid: None,
            last_command: last,
        };
        let c = planner.step(&input);
        let l = limits();
        assert!(c.v.is_finite() && c.omega.is_finite());
        assert!(c.v.abs() <= l.max_speed + 1e-12 && c.omega.abs() <= l.max_omega + 1e-12);
        assert!((c.v - last.v).abs() <= l.max_accel * DT + 1e-9);
        assert!((c.omega - last.omega).abs() <= l.max_alpha * DT + 1e-9);
        last = c;
        // Velocity along the contact normal: > 0 drives away from the wall, < 0 into it.
        match contact_normal(&pose, r, felt) {
            Some(n) => {
                let along = c.v * (pose.theta.cos() * n[0] + pose.theta.sin() * n[1]);
                let k = contact.get_or_insert(Contact {
                    steps_to_release: 0,
                    pushing_steps: 0,
                    released: false,
                });
                if along < -1e-9 {
                    k.pushing_steps += 1;
                }
                if along > 1e-9 {
                    k.released = true;
                }
                if !k.released {
                    k.steps_to_release += 1;
                }
            }
            None => out.contacts.extend(contact.take()),
        }
        // Unicycle, one Euler step.
        pose.x += c.v * pose.theta.cos() * DT;
        pose.y += c.v * pose.theta.sin() * DT;
        pose.theta = wrap_angle(pose.theta + c.omega * DT);
        let wall = pose.x.min(pose.y).min(SIDE - pose.x).min(SIDE - pose.y);
        out.min_wall_distance = out.min_wall_distance.min(wall);
        if !lidar {
            // Contact resolution: the penetration this step caused is felt next step.
            pose.x = pose.x.clamp(r - 0.01, SIDE - r + 0.01);
            pose.y = pose.y.clamp(r - 0.01, SIDE - r + 0.01);
        }
        let (cx, cy) = ((pose.x / CELL) as usize, (pose.y / CELL) as usize);
        visited[cy.min(n_cells - 1) * n_cells + cx.min(n_cells - 1)] = true;
        excursion = excursion.max((pose.x - window_start.x).hypot(pose.y - window_start.y));
        if (step + 1) % window == 0 {
            out.min_window_excursion = out.min_window_excursion.min(excursion);
            window_start = pose;
            excursion = 0.0;
        }
        if (step + 1) % (steps / 4) == 0 {
            out.coverage
                .push(visited.iter().filter(|v| **v).count() as f64 / visited.len() as f64);
        }
    }
    out.contacts.extend(contact);
    out.bounces = planner.bounces();
    out
}

/// With a lidar the random walk never touches a wall, never gets pinned and covers the box.
#[test]
fn lidar_robot_explores_the_box_without_hitting_or_pinning() {
    for seed in [2024, 1, 2, 3, 4, 5] {
        lidar_run(seed);
    }
}

/// One lidar run of 1000 s with `seed`; panics on the first broken promise.
fn lidar_run(seed: u64) {
    let mut p =
        planner_by_kind(PlannerKind::RandomWalk, limits(), seed).unwrap_or_else(|e| panic!("{e}"));
    let o = run(p.as_mut(), 20_000, true);
    let r = limits().radius;
    // The contact model tolerates r/2 of penetration; with a lidar the robot should not touch at all.
    assert!(
        o.min_wall_distance > r,
        "touched a wall: centre {} m from it",
        o.min_wall_distance
    );
    assert!(
        o.min_window_excursion > 0.3,
        "pinned: moved only {} m in a 10 s window",
        o.min_window_excursion
    );
    for w in o.coverage.windows(2) {
        assert!(w[1] > w[0], "coverage did not grow: {:?}", o.coverage);
    }
    // Cells the centre visits; the outer ring (centre within 0.25 m of a wall) is out of reach
    // for a 0.2 m robot that bounces 0.15 m short of walls, so at most 81 % is reachable.
    assert!(o.coverage[3] > 0.55, "{:?}", o.coverage);
    eprintln!(
        "lidar {seed}: min wall distance {:.3} m, min 10 s excursion {:.2} m, coverage {:?}, bounces {}",
        o.min_wall_distance, o.min_window_excursion, o.coverage, o.bounces
    );
}

/// Blind, touch alone: every contact is answered by a counted bounce-back that drives away from
/// the wall within the braking time and stops pushing into it, and the walk still covers the box.
#[test]
fn touch_only_robot_bounces_off_walls_and_keeps_exploring() {
    for seed in [7, 1, 2, 3, 4, 5] {
        touch_run(seed);
    }
}

/// One touch-only run of 1000 s with `seed`; panics on the first broken promise.
fn touch_run(seed: u64) {
    let mut p =
        planner_by_kind(PlannerKind::RandomWalk, limits(), seed).unwrap_or_else(|e| panic!("{e}"));
    let o = run(p.as_mut(), 20_000, false);
    let l = limits();
    // At full speed into a wall, the acceleration limit needs this many steps to stop.
    let braking = (l.max_speed / (l.max_accel * DT)).ceil() as usize;
    let contacts = o.contacts.len();
    let slowest = o.contacts.iter().map(|c| c.steps_to_release).max();
    let pushing = o.contacts.iter().map(|c| c.pushing_steps).max();
    let pushing_total: usize = o.contacts.iter().map(|c| c.pushing_steps).sum();
    eprintln!(
        "touch {seed}: {contacts} contacts, bounces {}, slowest release {slowest:?} steps, most pushing {pushing:?} steps ({pushing_total} in all), min 10 s excursion {:.2} m, coverage {:?}",
        o.bounces, o.min_window_excursion, o.coverage
    );
    assert!(
        contacts > 10,
        "only {contacts} contacts: the walk never reached the walls"
    );
    // Every felt contact starts a bounce-back, and the layer counts it.
    assert!(
        o.bounces as usize >= contacts,
        "{} bounces for {contacts} contacts",
        o.bounces
    );
    for (i, c) in o.contacts.iter().enumerate() {
        assert!(
            c.released && c.steps_to_release <= braking + 1,
            "contact {i} of {contacts}: {c:?}, no drive away from the wall within {} steps",
            braking + 1
        );
        assert!(
            c.pushing_steps <= braking,
            "contact {i} of {contacts}: {c:?}, kept pushing into the wall"
        );
    }
    assert!(
        o.min_window_excursion > 0.3,
        "pinned: moved only {} m in a 10 s window",
        o.min_window_excursion
    );
    for w in o.coverage.windows(2) {
        assert!(w[1] > w[0], "coverage did not grow: {:?}", o.coverage);
    }
    assert!(o.coverage[3] > 0.55, "{:?}", o.coverage);
}

/// The planner's randomness comes from its seed alone.
#[test]
fn same_seed_same_trajectory() {
    let trace = |seed| {
        let mut p = planner_by_kind(PlannerKind::RandomWalk, limits(), seed)
            .unwrap_or_else(|e| panic!("{e}"));
        let o = run(p.as_mut(), 2_000, true);
        (o.min_wall_distance, o.coverage, o.bounces)
    };
    assert_eq!(trace(5), trace(5));
}

/// A walk that ignores the scan is kept off the walls by the bounce-back layer's range trigger.
#[test]
fn lidar_bounce_back_alone_keeps_a_blind_walk_off_the_walls() {
    // The walk ignores the scan, so only the reactive layer keeps it off the walls.
    for seed in [11, 12, 13] {
        let walk = RandomWalk::new(
            limits(),
            RandomWalkConfig {
                scan_aware: false,
                ..Default::default()
            },
            seed,
        );
        let bb = BounceBack::new(walk, limits(), BounceBackConfig::default());
        let mut p = Limited::new(bb, limits());
        let o = run(&mut p, 20_000, true);
        let r = limits().radius;
        assert!(o.bounces > 20, "{}", o.bounces);
        // The contact model tolerates r/2 of penetration; with a lidar the robot should not touch at all.
        assert!(
            o.min_wall_distance > r,
            "touched a wall: centre {} m from it",
            o.min_wall_distance
        );
        assert!(
            o.min_window_excursion > 0.3,
            "pinned: {} m in a 10 s window",
            o.min_window_excursion
        );
        for w in o.coverage.windows(2) {
            assert!(w[1] > w[0], "coverage did not grow: {:?}", o.coverage);
        }
        eprintln!(
            "blind {seed}: min wall distance {:.3} m, min 10 s excursion {:.2} m, coverage {:?}, bounces {}",
            o.min_wall_distance, o.min_window_excursion, o.coverage, o.bounces
        );
    }
}
