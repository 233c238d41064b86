//! The simulated world: a disk robot with unicycle kinematics in the arena of algorithms §1.3
//! (a rectangle with axis-aligned squares), contact resolution, and the ground truth.
//!
//! One [`World::step`]: limit the command (speed, then acceleration), integrate the exact arc of
//! the unicycle in sub-steps no longer than half the robot radius (so the centre never crosses an
//! obstacle boundary in one sub-step and no obstacle can be tunnelled through), and after each
//! sub-step push the disk out of every wall and square it overlaps, along the contact normal,
//! repeating until nothing overlaps (corners need several passes). A sub-step that cannot be
//! resolved (the robot wedged in a gap narrower than itself) is undone.

use crate::broadphase::BucketGrid;
use crate::scenario::{Goal, Scenario};
use mole_types::{
    Contact, END_NONE, EndReason, MAX_CONTACTS, Pose2, RobotSpec, Square, TRUTH_END,
    TRUTH_GOAL_REACHED, TRUTH_IN_CONTACT, Truth, unicycle_arc, wrap_angle,
};

/// A wall or square within this gap of the rim (m) counts as touching.
pub const CONTACT_SKIN: f64 = 1e-3;
/// Contacts and per-obstacle depths one step records at most (a disk touches a handful).
const CONTACT_CAPACITY: usize = 64;
/// Pushes per sub-step (a corner needs two, a wedge a few more).
const MAX_PUSHES: usize = 32;
/// Upper bound on sub-steps per step (reached only with absurd speeds).
const MAX_SUBSTEPS: usize = 10_000;
/// Overlap treated as resolved (m): floating-point dust after a push.
const RESOLVED: f64 = 1e-12;

/// Which side of the arena a wall is: the contact normal points into the arena.
const WALLS: [(f64, f64); 4] = [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)];

/// The simulated world: the robot's true state, the obstacles and this step's contacts.
#[derive(Debug, Clone)]
pub struct World {
    width: f64,
    height: f64,
    robot: RobotSpec,
    dt: f64,
    goal: Option<Goal>,
    obstacles: Vec<Square>,
    grid: BucketGrid,
    /// Longest sub-step (m).
    max_substep: f64,
    pose: Pose2,
    v: f64,
    omega: f64,
    penetration: f64,
    /// This step's contacts, deepest first.
    contacts: Vec<Contact>,
    /// This step's deepest pre-resolution overlap per obstacle id (walls after the squares).
    depths: Vec<(u32, f64)>,
}

impl World {
    /// A world for `scenario` with the robot at the start pose, at rest.
    pub fn new(scenario: &Scenario) -> World {
        let robot = scenario.robot;
        let r = if robot.radius.is_finite() && robot.radius > 0.0 {
            robot.radius
        } else {
            0.0
        };
        let grid = BucketGrid::new(
            &scenario.obstacles,
            scenario.arena_width,
            scenario.arena_height,
            (2.0 * (r + CONTACT_SKIN)).max(0.25),
        );
        let mut world = World {
            width: scenario.arena_width,
            height: scenario.arena_height,
            robot,
            dt: scenario.dt,
            goal: scenario.goal,
            obstacles: scenario.obstacles.clone(),
            grid,
            max_substep: if r > 0.0 { 0.5 * r } else { 0.01 },
            pose: scenario.start,
            v: 0.0,
            omega: 0.0,
            penetration: 0.0,
            contacts: Vec::with_capacity(CONTACT_CAPACITY),
            depths: Vec::with_capacity(CONTACT_CAPACITY),
        };
        world.collect_contacts();
        world
    }

    /// A world for `scenario` that goes on from `truth`, the last step a crashed world published:
    /// the robot's pose, velocities and penetration are all the state a step starts from (the
    /// contacts are found anew by the next step).
    pub fn resume(scenario: &Scenario, truth: &Truth) -> World {
        let mut world = World::new(scenario);
        world.pose = Pose2::new(truth.x, truth.y, truth.theta);
        (world.v, world.omega) = (truth.v, truth.omega);
        world.penetration = truth.penetration;
        world.depths.clear();
        world.collect_contacts();
        world
    }

    /// Puts the robot at `pose`, at rest, without resolving overlaps (tests and resets).
    pub fn set_pose(&mut self, pose: Pose2) {
        self.pose = Pose2::new(pose.x, pose.y, wrap_angle(pose.theta));
        self.v = 0.0;
        self.omega = 0.0;
        self.depths.clear();
        self.collect_contacts();
    }

    /// One step of Δt: clamp the command to the speed and acceleration limits, integrate the
    /// unicycle's exact arc in short sub-steps, resolve contacts after each, record the contacts.
    pub fn step(&mut self, v_cmd: f64, omega_cmd: f64) {
        let dt = if self.dt.is_finite() && self.dt > 0.0 {
            self.dt
        } else {
            0.0
        };
        self.v = limit(
            self.v,
            v_cmd,
            self.robot.max_speed,
            self.robot.max_accel,
            dt,
        );
        self.omega = limit(
            self.omega,
            omega_cmd,
            self.robot.max_omega,
            self.robot.max_alpha,
            dt,
        );

        self.depths.clear();
        let distance = self.v.abs() * dt;
        let n = ((distance / self.max_substep).ceil() as usize).clamp(1, MAX_SUBSTEPS);
        let h = dt / n as f64;
        for _ in 0..n {
            let (x0, y0) = (self.pose.x, self.pose.y);
            self.pose = unicycle_arc(self.pose, self.v, self.omega, h);
            if self.resolve() > 0.5 * CONTACT_SKIN {
                // Wedged: undo the translation of this sub-step, keep the turn.
                self.pose.x = x0;
                self.pose.y = y0;
            }
        }
        self.collect_contacts();
    }

    /// The true pose.
    pub fn pose(&self) -> Pose2 {
        self.pose
    }

    /// The velocities applied in the last step, after the limits: `(v, ω)`. These are the wheel
    /// velocities; when an obstacle blocks the robot, its actual motion is less.
    pub fn velocity(&self) -> (f64, f64) {
        (self.v, self.omega)
    }

    /// Deepest overlap of the robot with a wall or square left after resolution (m).
    pub fn penetration(&self) -> f64 {
        self.penetration
    }

    /// Every wall and square touching the robot after the last step, deepest first.
    pub fn contacts(&self) -> &[Contact] {
        &self.contacts
    }

    /// Whether the robot centre is within the goal tolerance (false without a goal).
    pub fn goal_reached(&self) -> bool {
        self.goal
            .is_some_and(|g| (self.pose.x - g.x).hypot(self.pose.y - g.y) <= g.tolerance)
    }

    /// Fills the pose, velocities, penetration and contacts (deepest first, at most
    /// `MAX_CONTACTS`) and sets or clears `TRUTH_IN_CONTACT` and `TRUTH_GOAL_REACHED`; leaves
    /// `header`, `TRUTH_END`, `end_reason` and `cmd_latency_ns` to the caller.
    /// Fills `world/truth` for a step: the state, the loop latency of the command that drove it,
    /// and, on the last step, why the run ended.
    pub fn write_step(&self, truth: &mut Truth, latency_ns: u64, end: Option<EndReason>) {
        self.write_truth(truth);
        truth.cmd_latency_ns = latency_ns;
        truth.end_reason = end.map_or(END_NONE, EndReason::code);
        truth.flags = match end {
            Some(_) => truth.flags | TRUTH_END,
            None => truth.flags & !TRUTH_END,
        };
    }

    pub fn write_truth(&self, truth: &mut Truth) {
        truth.x = self.pose.x;
        truth.y = self.pose.y;
        truth.theta = self.pose.theta;
        truth.v = self.v;
        truth.omega = self.omega;
        truth.penetration = self.penetration;
        let n = self.contacts.len().min(MAX_CONTACTS);
        truth.contacts[..n].copy_from_slice(&self.contacts[..n]);
        truth.contacts[n..].fill(Contact::default());
        truth.n_contacts = n as u32;
        truth._pad = 0;
        let mut flags = truth.flags & !(TRUTH_IN_CONTACT | TRUTH_GOAL_REACHED);
        if !self.contacts.is_empty() {
            flags |= TRUTH_IN_CONTACT;
        }
        if self.goal_reached() {
            flags |= TRUTH_GOAL_REACHED;
        }
        truth.flags = flags;
    }

    /// Pushes the disk out of the wall or square it overlaps most, again and again until nothing
    /// overlaps (deepest first, so a flat face wins over the corner of its neighbour and the robot
    /// slides over seams between touching squares); records each overlap as a depth and returns
    /// the deepest overlap left.
    fn resolve(&mut self) -> f64 {
        let r = self.robot.radius;
        let wall_base = self.obstacles.len() as u32;
        for _ in 0..MAX_PUSHES {
            let (x, y) = (self.pose.x, self.pose.y);
            let mut deepest: Option<((f64, f64), f64)> = None;
            let mut consider =
                |depths: &mut Vec<(u32, f64)>, id: u32, normal: (f64, f64), gap: f64| {
                    if gap < -RESOLVED {
                        record_depth(depths, id, -gap);
                        if deepest.is_none_or(|d| gap < d.1) {
                            deepest = Some((normal, gap));
                        }
                    }
                };
            for (k, &normal) in WALLS.iter().enumerate() {
                let gap = wall_gap(x, y, r, self.width, self.height, k);
                consider(&mut self.depths, wall_base + k as u32, normal, gap);
            }
            for &i in self.grid.query(x, y, r + CONTACT_SKIN) {
                let (normal, gap) = square_gap(&self.obstacles[i as usize], x, y, r);
                consider(&mut self.depths, i, normal, gap);
            }
            let Some((normal, gap)) = deepest else { break };
            self.pose.x -= gap * normal.0;
            self.pose.y -= gap * normal.1;
        }
        self.deepest_overlap()
    }

    fn deepest_overlap(&mut self) -> f64 {
        let r = self.robot.radius;
        let (x, y) = (self.pose.x, self.pose.y);
        let mut deepest = 0.0_f64;
        for k in 0..WALLS.len() {
            deepest = deepest.max(-wall_gap(x, y, r, self.width, self.height, k));
        }
        for &i in self.grid.query(x, y, r + CONTACT_SKIN) {
            deepest = deepest.max(-square_gap(&self.obstacles[i as usize], x, y, r).1);
        }
        deepest
    }

    /// Records every wall and square within the skin of the rim, deepest first, and the
    /// remaining penetration.
    fn collect_contacts(&mut self) {
        let r = self.robot.radius;
        let (x, y) = (self.pose.x, self.pose.y);
        let wall_base = self.obstacles.len() as u32;
        self.contacts.clear();
        let mut deepest = 0.0_f64;
        let depths = &self.depths;
        let contacts = &mut self.contacts;
        let mut add = |id: u32, normal: (f64, f64), gap: f64| {
            deepest = deepest.max(-gap);
            if gap <= CONTACT_SKIN && contacts.len() < CONTACT_CAPACITY {
                let depth = depths.iter().find(|d| d.0 == id).map_or(0.0, |d| d.1);
                contacts.push(Contact {
                    px: x - normal.0 * r,
                    py: y - normal.1 * r,
                    nx: normal.0,
                    ny: normal.1,
                    depth,
                });
            }
        };
        for (k, &normal) in WALLS.iter().enumerate() {
            add(
                wall_base + k as u32,
                normal,
                wall_gap(x, y, r, self.width, self.height, k),
            );
        }
        for &i in self.grid.query(x, y, r + CONTACT_SKIN) {
            let (normal, gap) = square_gap(&self.obstacles[i as usize], x, y, r);
            add(i, normal, gap);
        }
        self.penetration = deepest;
        self.contacts
            .sort_unstable_by(|a, b| b.depth.total_cmp(&a.depth));
    }
}

/// Limits a velocity command: first to `±max`, then the change from `current` to `±rate·dt`.
/// A non-finite command counts as 0.
fn limit(current: f64, command: f64, max: f64, rate: f64, dt: f64) -> f64 {
    let max = if max.is_finite() { max.abs() } else { 0.0 };
    let target = if command.is_finite() {
        command.clamp(-max, max)
    } else {
        0.0
    };
    let step = if rate.is_finite() {
        rate.abs() * dt
    } else {
        f64::INFINITY
    };
    let next = current + (target - current).clamp(-step, step);
    next.clamp(-max, max)
}

/// Gap between the rim and wall `k` (negative: overlap); walls in the order of [`WALLS`].
fn wall_gap(x: f64, y: f64, r: f64, width: f64, height: f64, k: usize) -> f64 {
    match k {
        0 => x - r,
        1 => width - x - r,
        2 => y - r,
        _ => height - y - r,
    }
}

/// Unit normal from the square into the disk centre, and the gap between rim and square
/// (negative: overlap). A centre inside the square leaves through the nearest face.
fn square_gap(o: &Square, x: f64, y: f64, r: f64) -> ((f64, f64), f64) {
    let h = o.side / 2.0;
    let (dx, dy) = (x - o.cx, y - o.cy);
    let (ex, ey) = (dx - dx.clamp(-h, h), dy - dy.clamp(-h, h));
    let d = ex.hypot(ey);
    if d > 0.0 {
        return ((ex / d, ey / d), d - r);
    }
    // Inside: the face with the least penetration.
    let faces = [
        (h - dx, (1.0, 0.0)),
        (h + dx, (-1.0, 0.0)),
        (h - dy, (0.0, 1.0)),
        (h + dy, (0.0, -1.0)),
    ];
    let mut best = faces[0];
    for f in &faces[1..] {
        if f.0 < best.0 {
            best = *f;
        }
    }
    (best.1, -best.0 - r)
}

fn record_depth(depths: &mut Vec<(u32, f64)>, id: u32, depth: f64) {
    if let Some(d) = depths.iter_mut().find(|d| d.0 == id) {
        d.1 = d.1.max(depth);
    } else if depths.len() < depths.capacity() {
        depths.push((id, depth));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::{distance_to_square, parse_scenario};
    use approx::assert_abs_diff_eq;
    use proptest::prelude::*;
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};
    use std::path::Path;

    fn scenario(text: &str) -> Scenario {
        match parse_scenario(text, Path::new("test.toml")) {
            Ok(s) => s,
            Err(e) => panic!("{e}"),
        }
    }

    /// A robot that reaches full speed in one step.
    const AGILE: &str = "[robot]\nradius = 0.2\nmax_speed = 0.5\nmax_omega = 2.0\nmax_accel = 1000.0\nmax_alpha = 1000.0\n";

    /// Deepest overlap by brute force over every obstacle (checks the broad phase too).
    fn brute_penetration(s: &Scenario, p: Pose2) -> f64 {
        let r = s.robot.radius;
        let mut deepest = [
            p.x - r,
            s.arena_width - p.x - r,
            p.y - r,
            s.arena_height - p.y - r,
        ]
        .into_iter()
        .fold(0.0_f64, |a, g| a.max(-g));
        for o in &s.obstacles {
            deepest = deepest.max(r - distance_to_square(o, p.x, p.y));
        }
        deepest
    }

    #[test]
    fn new_world_is_at_rest_at_the_start() {
        let s = scenario("[start]\nx = 2.0\ny = 3.0\ntheta = 0.5\n");
        let w = World::new(&s);
        assert_eq!(w.pose(), Pose2::new(2.0, 3.0, 0.5));
        assert_eq!(w.velocity(), (0.0, 0.0));
        assert!(w.contacts().is_empty());
        assert_eq!(w.penetration(), 0.0);
        assert!(!w.goal_reached());
    }

    /// A world resumed from a step's truth (a restart after a crash) steps exactly as the one
    /// that published it, also from a step in contact with a wall (velocities under
    /// acceleration limits and penetration are carried over; contacts are found anew).
    #[test]
    fn a_world_resumed_from_its_truth_goes_on_bit_identically() {
        let s = scenario("[start]\nx = 1.0\ny = 1.0\ntheta = 3.5\n");
        let command = |i: usize| {
            let t = i as f64;
            (0.4 + 0.1 * (t * 0.05).sin(), 0.6 * (t * 0.02).cos())
        };
        let mut truth: Box<Truth> = bytemuck::zeroed_box();
        let mut resumed_in_contact = 0;
        for crash in (19..400).step_by(20) {
            // Not a clone: a cloned Vec loses the capacity the world keeps to never allocate.
            let mut original = World::new(&s);
            for i in 0..=crash {
                let (v, omega) = command(i);
                original.step(v, omega);
            }
            original.write_step(&mut truth, 0, None);
            let mut resumed = World::resume(&s, &truth);
            resumed_in_contact += usize::from(!original.contacts().is_empty());
            for i in crash + 1..crash + 30 {
                let (v, omega) = command(i);
                original.step(v, omega);
                resumed.step(v, omega);
                assert_eq!(
                    resumed.pose(),
                    original.pose(),
                    "crash at {crash}, step {i}"
                );
                assert_eq!(resumed.velocity(), original.velocity(), "step {i}");
                assert_eq!(resumed.penetration(), original.penetration(), "step {i}");
                assert_eq!(resumed.contacts(), original.contacts(), "step {i}");
            }
        }
        assert!(
            resumed_in_contact > 0,
            "never resumed in contact: the test sees too little"
        );
    }

    #[test]
    fn straight_line_is_exact() {
        let s = scenario(&format!(
            "{AGILE}[start]\nx = 2.0\ny = 2.0\ntheta = {FRAC_PI_4}\n"
        ));
        let mut w = World::new(&s);
        for _ in 0..100 {
            w.step(0.5, 0.0);
        }
        let d = 0.5 * 1.0;
        assert_abs_diff_eq!(w.pose().x, 2.0 + d * FRAC_PI_4.cos(), epsilon = 1e-12);
        assert_abs_diff_eq!(w.pose().y, 2.0 + d * FRAC_PI_4.sin(), epsilon = 1e-12);
        assert_abs_diff_eq!(w.pose().theta, FRAC_PI_4, epsilon = 1e-15);
    }

    #[test]
    fn arc_is_exact() {
        // v = 0.5, ω = 1 → radius 0.5; a quarter turn from (5, 4) heading +x ends at (5.5, 4.5).
        let s = scenario(&format!("{AGILE}[start]\nx = 5.0\ny = 4.0\n"));
        let mut w = World::new(&s);
        let steps = (FRAC_PI_2 / 0.01).round() as usize; // 157 steps: θ = 1.57
        for _ in 0..steps {
            w.step(0.5, 1.0);
        }
        let th = steps as f64 * 0.01;
        assert_abs_diff_eq!(w.pose().x, 5.0 + 0.5 * th.sin(), epsilon = 1e-12);
        assert_abs_diff_eq!(w.pose().y, 4.0 + 0.5 * (1.0 - th.cos()), epsilon = 1e-12);
        assert_abs_diff_eq!(w.pose().theta, th, epsilon = 1e-12);
        // A full circle comes back to the start.
        let mut w = World::new(&s);
        let n = (2.0 * PI / 0.01).round() as usize;
        let mut p = Pose2::new(5.0, 4.0, 0.0);
        for _ in 0..n {
            w.step(0.5, 1.0);
            p = unicycle_arc(p, 0.5, 1.0, 0.01);
        }
        assert_abs_diff_eq!(w.pose().x, p.x, epsilon = 1e-12);
        assert_abs_diff_eq!(w.pose().y, p.y, epsilon = 1e-12);
        assert!((w.pose().x - 5.0).hypot(w.pose().y - 4.0) < 0.01);
    }

    #[test]
    fn velocity_is_clamped_and_acceleration_limited() {
        // max_accel 2 m/s², dt 0.01 → 0.02 m/s per step; max_alpha 8 → 0.08 rad/s per step.
        let s = scenario("[start]\nx = 5.0\ny = 5.0\n");
        let mut w = World::new(&s);
        w.step(10.0, -10.0);
        assert_abs_diff_eq!(w.velocity().0, 0.02, epsilon = 1e-15);
        assert_abs_diff_eq!(w.velocity().1, -0.08, epsilon = 1e-15);
        for _ in 0..100 {
            w.step(10.0, -10.0);
        }
        assert_eq!(w.velocity(), (0.5, -2.0));
        // Braking is limited too.
        w.step(0.0, 0.0);
        assert_abs_diff_eq!(w.velocity().0, 0.48, epsilon = 1e-12);
        assert_abs_diff_eq!(w.velocity().1, -1.92, epsilon = 1e-12);
        // Non-finite commands count as 0.
        w.step(f64::NAN, f64::INFINITY);
        assert_abs_diff_eq!(w.velocity().0, 0.46, epsilon = 1e-12);
        assert_abs_diff_eq!(w.velocity().1, -1.84, epsilon = 1e-12);
        assert!(w.pose().x.is_finite());
    }

    #[test]
    fn driving_into_a_wall_stops_at_the_wall_with_a_contact() {
        let s = scenario(&format!("{AGILE}[start]\nx = 9.0\ny = 5.0\n"));
        let mut w = World::new(&s);
        for _ in 0..400 {
            w.step(0.5, 0.0);
            assert!(w.penetration() <= 1e-3);
        }
        assert_abs_diff_eq!(w.pose().x, 10.0 - 0.2, epsilon = 1e-9);
        assert_eq!(w.contacts().len(), 1);
        let c = w.contacts()[0];
        assert_eq!((c.nx, c.ny), (-1.0, 0.0));
        assert_abs_diff_eq!(c.px, 10.0, epsilon = 1e-9);
        assert_abs_diff_eq!(c.py, 5.0, epsilon = 1e-12);
        // Each step pushes the rim 5 mm into the wall before resolution.
        assert_abs_diff_eq!(c.depth, 0.005, epsilon = 1e-9);
        // Backing off: still touching after the first step? No: 5 mm away is beyond the skin.
        for _ in 0..2 {
            w.step(-0.5, 0.0);
        }
        assert!(w.contacts().is_empty());
    }

    #[test]
    fn sliding_along_a_wall_keeps_the_tangential_motion() {
        // Heading 30° into the bottom wall: y stays at r, x advances by v·cos 30° per second.
        let s = scenario(&format!(
            "{AGILE}[start]\nx = 1.0\ny = 0.2\ntheta = {}\n",
            -PI / 6.0
        ));
        let mut w = World::new(&s);
        for _ in 0..200 {
            w.step(0.5, 0.0);
            assert!(w.penetration() <= 1e-3);
        }
        assert_abs_diff_eq!(w.pose().y, 0.2, epsilon = 1e-9);
        assert_abs_diff_eq!(
            w.pose().x,
            1.0 + 2.0 * 0.5 * (PI / 6.0).cos(),
            epsilon = 1e-9
        );
        let c = w.contacts()[0];
        assert_eq!((c.nx, c.ny), (0.0, 1.0));
        assert_abs_diff_eq!(c.depth, 0.005 * 0.5, epsilon = 1e-9);
    }

    #[test]
    fn sliding_along_a_row_of_touching_squares_does_not_snag() {
        let mut obstacles = String::from("obstacles = [");
        for i in 0..12 {
            obstacles.push_str(&format!(
                "{{ x = {}, y = 5.25, side = 0.5 }},",
                2.25 + 0.5 * i as f64
            ));
        }
        obstacles.push_str("]\n");
        // Heading 10° down onto the row's top face at y = 5.5.
        let s = scenario(&format!(
            "{obstacles}{AGILE}[start]\nx = 2.0\ny = 5.7\ntheta = {}\n",
            -10f64.to_radians()
        ));
        let mut w = World::new(&s);
        for _ in 0..800 {
            w.step(0.5, 0.0);
            assert!(w.penetration() <= 1e-3);
        }
        assert_abs_diff_eq!(w.pose().y, 5.7, epsilon = 1e-9);
        assert_abs_diff_eq!(
            w.pose().x,
            2.0 + 4.0 * 10f64.to_radians().cos(),
            epsilon = 1e-6
        );
        assert!(w.contacts().iter().all(|c| c.ny > 0.99));
    }

    #[test]
    fn pushing_into_an_arena_corner_resolves_both_walls() {
        let s = scenario(&format!(
            "{AGILE}[start]\nx = 1.0\ny = 1.0\ntheta = {}\n",
            -3.0 * FRAC_PI_4
        ));
        let mut w = World::new(&s);
        for _ in 0..300 {
            w.step(0.5, 0.0);
            assert!(w.penetration() <= 1e-3);
        }
        assert_abs_diff_eq!(w.pose().x, 0.2, epsilon = 1e-9);
        assert_abs_diff_eq!(w.pose().y, 0.2, epsilon = 1e-9);
        let mut normals: Vec<(f64, f64)> = w.contacts().iter().map(|c| (c.nx, c.ny)).collect();
        normals.sort_by(|a, b| a.partial_cmp(b).unwrap());
        assert_eq!(normals, vec![(0.0, 1.0), (1.0, 0.0)]);
    }

    #[test]
    fn pushing_into_the_corner_between_two_touching_squares() {
        // An L: a square and its neighbour above it on the left form an inner corner at (5, 5).
        let s = scenario(&format!(
            "obstacles = [{{ x = 5.5, y = 4.5, side = 1.0 }}, {{ x = 4.5, y = 5.5, side = 1.0 }}, \
             {{ x = 4.5, y = 4.5, side = 1.0 }}]\n{AGILE}[start]\nx = 6.0\ny = 6.0\ntheta = {}\n",
            -3.0 * FRAC_PI_4
        ));
        let mut w = World::new(&s);
        for _ in 0..400 {
            w.step(0.5, 0.0);
            assert!(w.penetration() <= 1e-3, "{}", w.penetration());
        }
        assert_abs_diff_eq!(w.pose().x, 5.2, epsilon = 1e-9);
        assert_abs_diff_eq!(w.pose().y, 5.2, epsilon = 1e-9);
        assert!(w.contacts().len() >= 2);
        assert!(brute_penetration(&s, w.pose()) <= 1e-3);
    }

    #[test]
    fn a_gap_narrower_than_the_robot_stops_it() {
        // Two squares 0.3 m apart; the robot (0.4 m wide) drives straight into the gap.
        let s = scenario(&format!(
            "obstacles = [{{ x = 5.0, y = 4.35, side = 1.0 }}, {{ x = 5.0, y = 5.65, side = 1.0 }}]\n\
             {AGILE}[start]\nx = 3.0\ny = 5.0\n"
        ));
        let mut w = World::new(&s);
        for _ in 0..600 {
            w.step(0.5, 0.0);
            assert!(w.penetration() <= 1e-3);
        }
        assert!(
            w.pose().x < 4.5 - 0.2 + 0.1,
            "stuck at the mouth, x = {}",
            w.pose().x
        );
        assert!(w.pose().x > 4.0);
        assert_abs_diff_eq!(w.pose().y, 5.0, epsilon = 1e-9);
        assert_eq!(w.contacts().len(), 2);
    }

    #[test]
    fn a_thin_obstacle_is_not_tunnelled_at_high_speed() {
        // 5 m/s and Δt = 0.1 s: 0.5 m per step, fifty times the obstacle's 1 cm thickness.
        let s = scenario(
            "obstacles = [{ x = 5.0, y = 5.0, side = 0.01 }]\n[sim]\ndt = 0.1\n[robot]\nradius = 0.2\n\
             max_speed = 5.0\nmax_accel = 1000.0\n[start]\nx = 1.0\ny = 5.0\n",
        );
        let mut w = World::new(&s);
        for _ in 0..40 {
            w.step(5.0, 0.0);
            assert!(w.penetration() <= 1e-3);
            assert!(w.pose().x < 5.0, "tunnelled to x = {}", w.pose().x);
        }
        assert_abs_diff_eq!(w.pose().x, 5.0 - 0.005 - 0.2, epsilon = 1e-9);
    }

    #[test]
    fn goal_flag_follows_the_tolerance() {
        let s = scenario(&format!(
            "{AGILE}[start]\nx = 1.0\ny = 5.0\n[goal]\nx = 2.0\ny = 5.0\ntolerance = 0.3\n"
        ));
        let mut w = World::new(&s);
        let mut truth: Truth = bytemuck::Zeroable::zeroed();
        let mut first = None;
        for k in 0..100 {
            w.step(0.5, 0.0);
            w.write_truth(&mut truth);
            assert_eq!(w.goal_reached(), truth.flags & TRUTH_GOAL_REACHED != 0);
            if w.goal_reached() && first.is_none() {
                first = Some(k);
            }
        }
        // 0.7 m at 0.5 m/s: step 140 is beyond 100; reached at x >= 1.7, i.e. after 1.4 s.
        assert_eq!(first, None);
        for _ in 0..50 {
            w.step(0.5, 0.0);
        }
        assert!(w.goal_reached());
        w.write_truth(&mut truth);
        assert!(truth.flags & TRUTH_GOAL_REACHED != 0);
        let no_goal = World::new(&scenario("[start]\nx = 2.0\ny = 5.0\n"));
        assert!(!no_goal.goal_reached());
    }

    #[test]
    fn write_truth_fills_state_and_contacts() {
        let s = scenario(&format!(
            "{AGILE}[start]\nx = 1.0\ny = 1.0\ntheta = {}\n",
            -3.0 * FRAC_PI_4
        ));
        let mut w = World::new(&s);
        for _ in 0..300 {
            w.step(0.5, 0.3);
        }
        let mut truth: Truth = bytemuck::Zeroable::zeroed();
        truth.flags = mole_types::TRUTH_END | TRUTH_GOAL_REACHED;
        truth.header.seq = 9;
        truth.end_reason = 1;
        truth.cmd_latency_ns = 5;
        truth.contacts[7].depth = 3.0;
        w.write_truth(&mut truth);
        assert_eq!(
            (truth.x, truth.y, truth.theta),
            (w.pose().x, w.pose().y, w.pose().theta)
        );
        assert_eq!((truth.v, truth.omega), w.velocity());
        assert_eq!(truth.penetration, w.penetration());
        assert_eq!(truth.n_contacts as usize, w.contacts().len());
        assert_eq!(truth.contacts(), w.contacts());
        assert!(
            truth
                .contacts()
                .windows(2)
                .all(|c| c[0].depth >= c[1].depth),
            "deepest first"
        );
        assert_eq!(
            truth.contacts[7],
            Contact::default(),
            "stale contacts cleared"
        );
        assert_eq!(
            truth.flags,
            mole_types::TRUTH_END | TRUTH_IN_CONTACT,
            "goal cleared, end kept"
        );
        assert_eq!(
            (truth.header.seq, truth.end_reason, truth.cmd_latency_ns),
            (9, 1, 5)
        );
        assert_eq!(mole_types::Message::validate(&truth), Ok(()));
        for c in truth.contacts() {
            assert_abs_diff_eq!(c.nx.hypot(c.ny), 1.0, epsilon = 1e-12);
            // The contact point is on the rim.
            assert_abs_diff_eq!((c.px - truth.x).hypot(c.py - truth.y), 0.2, epsilon = 1e-12);
        }
        w.set_pose(Pose2::new(5.0, 5.0, 0.0));
        w.write_truth(&mut truth);
        assert_eq!(truth.n_contacts, 0);
        assert_eq!(truth.flags & TRUTH_IN_CONTACT, 0);
    }

    #[test]
    fn contacts_are_deepest_first() {
        // Into the bottom wall at 60° below the heading, beside a square on the right.
        let s = scenario(&format!(
            "obstacles = [{{ x = 2.0, y = 0.5, side = 1.0 }}]\n{AGILE}[start]\nx = 1.3\ny = 0.25\ntheta = {}\n",
            -PI / 3.0
        ));
        let mut w = World::new(&s);
        for _ in 0..20 {
            w.step(0.5, 0.0);
        }
        let c = w.contacts();
        assert_eq!(c.len(), 2);
        assert!(c[0].depth > c[1].depth);
        assert_eq!(
            (c[0].nx, c[0].ny),
            (0.0, 1.0),
            "the wall takes the motion head on"
        );
    }

    fn cluttered() -> Scenario {
        match crate::scenario::bundled_scenario("cluttered") {
            Ok(s) => s,
            Err(e) => panic!("{e}"),
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        #[test]
        fn never_more_than_a_millimetre_of_penetration(
            sx in 0.0f64..1.0, sy in 0.0f64..1.0, st in -PI..PI,
            commands in proptest::collection::vec((-1.0f64..1.0, -1.0f64..1.0, 20usize..250), 1..6),
        ) {
            let s = cluttered();
            let mut w = World::new(&s);
            // A random free start: scan from the sampled point for the first free pose.
            let mut start = None;
            'search: for k in 0..400 {
                let x = 0.2 + ((sx + 0.137 * k as f64) % 1.0) * (s.arena_width - 0.4);
                let y = 0.2 + ((sy + 0.291 * k as f64) % 1.0) * (s.arena_height - 0.4);
                if s.disk_is_free(x, y) {
                    start = Some(Pose2::new(x, y, st));
                    break 'search;
                }
            }
            let Some(start) = start else { return Err(TestCaseError::reject("no free start")) };
            w.set_pose(start);
            for (v, omega, ticks) in commands {
                // Flat out (commands beyond the limit too), gently curving, long enough to hit
                // things.
                let v = v.signum() * (0.5 + 0.5 * v.abs()) * s.robot.max_speed * 1.5;
                for _ in 0..ticks {
                    w.step(v, 0.3 * omega * s.robot.max_omega);
                    let p = w.pose();
                    prop_assert!(w.penetration() <= 1e-3, "penetration {}", w.penetration());
                    let brute = brute_penetration(&s, p);
                    prop_assert!(brute <= 1e-3, "brute-force penetration {} at {:?}", brute, p);
                    prop_assert!((brute - w.penetration()).abs() < 1e-9);
                    for c in w.contacts() {
                        prop_assert!(c.depth >= 0.0);
                        prop_assert!((c.nx.hypot(c.ny) - 1.0).abs() < 1e-9);
                    }
                }
            }
        }
    }

    #[test]
    fn step_and_write_truth_do_not_allocate() {
        let s = cluttered();
        let mut w = World::new(&s);
        let mut truth: Box<Truth> = bytemuck::zeroed_box();
        let before = crate::alloc_count::allocations();
        let mut touched = 0;
        for k in 0..3000 {
            w.step(0.5, if (k / 200) % 2 == 0 { 0.3 } else { -0.7 });
            w.write_truth(&mut truth);
            touched += usize::from(!w.contacts().is_empty());
        }
        assert_eq!(crate::alloc_count::allocations(), before);
        assert!(touched > 0, "the run should hit something");
    }

    /// Through 1024 squares, every one of 5000 steps ends in a finite pose resolved exactly as a
    /// brute-force check over all squares says, the robot keeps moving and touching squares, and
    /// the broad phase hands the narrow phase only the few squares beside the robot (how fast
    /// that is, the `world` benchmark measures).
    #[test]
    fn a_thousand_square_maze_resolves_every_step_from_a_few_candidates() {
        // 32 × 32 blocks of 0.1 m on a 0.5 m lattice: 1024 squares, lanes as wide as the robot.
        let mut text =
            format!("{AGILE}[arena]\nwidth = 16.25\nheight = 16.25\n[start]\nx = 0.25\ny = 0.25\n");
        for i in 0..32 {
            for j in 0..32 {
                let (x, y) = (0.75 + 0.5 * i as f64, 0.75 + 0.5 * j as f64);
                text.push_str(&format!("[[obstacles]]\nx = {x}\ny = {y}\nside = 0.1\n"));
            }
        }
        let s = scenario(&text);
        assert_eq!(s.obstacles.len(), 1024);
        let reach = s.robot.radius + CONTACT_SKIN;
        let mut w = World::new(&s);
        let (mut travelled, mut touching, mut most_candidates) = (0.0, 0, 0);
        for k in 0..5000 {
            let before = w.pose();
            w.step(0.5, if k % 300 < 150 { 0.4 } else { -0.5 });
            let p = w.pose();
            assert!(
                p.x.is_finite() && p.y.is_finite() && p.theta.is_finite(),
                "step {k}: {p:?}"
            );
            assert!(w.penetration() <= 1e-3, "step {k}: {}", w.penetration());
            let brute = brute_penetration(&s, p);
            assert!(
                (brute - w.penetration()).abs() < 1e-9,
                "step {k}: broad phase missed a square, {brute} vs {}",
                w.penetration()
            );
            travelled += (p.x - before.x).hypot(p.y - before.y);
            touching += usize::from(!w.contacts().is_empty());
            most_candidates = most_candidates.max(w.grid.query(p.x, p.y, reach).len());
        }
        // 50 s at up to 0.5 m/s: it slides along the lanes rather than sticking on a square.
        assert!(travelled > 10.0, "travelled {travelled} m");
        assert!(touching > 1000, "touched squares in {touching} steps");
        // The query box spans at most 2 × 2 buckets, which hold at most 3 × 3 lattice squares.
        assert!(
            most_candidates <= 9,
            "{most_candidates} of 1024 squares checked"
        );
    }
}
