use super::*;
use crate::obstacles::test_support::{scan_uniform, scan_wall_ahead};
use crate::{Limited, RandomWalk, RandomWalkConfig};
use mole_types::{MODE_EXPLORE, MODE_IDLE, Pose2, Scan, Tactile};
use proptest::prelude::Just;

const DT: f64 = 0.01;

fn limits() -> RobotLimits {
    RobotLimits::default()
}

/// Always wishes to drive straight ahead at 0.4 m/s; counts the re-plans it is asked for.
#[derive(Debug, Default)]
struct Forward {
    replans: u32,
}

impl Planner for Forward {
    fn kind(&self) -> PlannerKind {
        PlannerKind::RandomWalk
    }
    fn step(&mut self, _input: &PlannerInput) -> Command {
        Command {
            v: 0.4,
            omega: 0.0,
            mode: MODE_EXPLORE,
        }
    }
    fn replan(&mut self) {
        self.replans += 1;
    }
}

/// The layer around [`Forward`], inside [`Limited`] as `build_planner` stacks it.
fn forward_stack() -> Limited<BounceBack<Forward>> {
    let bb = BounceBack::new(Forward::default(), limits(), BounceBackConfig::default());
    Limited::new(bb, limits())
}

/// Runs one step with `scan` and `tactile`, moves `pose` by the command, checks the limits.
struct Rig {
    stack: Limited<BounceBack<Forward>>,
    pose: Pose2,
    tick: u64,
    last: Command,
}

impl Rig {
    fn new() -> Self {
        Self {
            stack: forward_stack(),
            pose: Pose2::new(1.0, 1.0, 0.0),
            tick: 0,
            last: Command::STOP,
        }
    }
    /// The bounce-back layer.
    fn bb(&self) -> &BounceBack<Forward> {
        self.stack.inner()
    }
    fn step(&mut self, scan: Option<&Scan>, tactile: Option<&Tactile>) -> Command {
        let input = PlannerInput {
            tick: self.tick,
            dt: DT,
            pose: self.pose,
            scan,
            tactile,
            grid: None,
            last_command: self.last,
        };
        let c = self.stack.step(&input);
        let l = limits();
        assert!(
            c.v.abs() <= l.max_speed && c.omega.abs() <= l.max_omega,
            "{c:?}"
        );
        assert!(
            (c.v - self.last.v).abs() <= l.max_accel * DT + 1e-12,
            "{:?} -> {c:?}",
            self.last
        );
        assert!((c.omega - self.last.omega).abs() <= l.max_alpha * DT + 1e-12);
        self.pose.theta = wrap_angle(self.pose.theta + c.omega * DT);
        self.pose.x += c.v * self.pose.theta.cos() * DT;
        self.pose.y += c.v * self.pose.theta.sin() * DT;
        self.tick += 1;
        self.last = c;
        c
    }
}

#[test]
fn source_position_update_drops_x_t() {
    let (x, v, alpha, dt) = ([2.0, 3.0], [0.4, -0.2], 0.5, 0.1);
    assert_eq!(bounce_back_velocity(v, alpha), [-0.2, 0.1]);
    let corrected = bounce_back_position(x, v, alpha, dt, PositionUpdate::Corrected);
    let seed = bounce_back_position(x, v, alpha, dt, PositionUpdate::Source);
    assert!((corrected[0] - 1.98).abs() < 1e-12 && (corrected[1] - 3.01).abs() < 1e-12);
    // The source's form is the displacement alone: the robot would jump back to the origin.
    assert!((seed[0] + 0.02).abs() < 1e-12 && (seed[1] - 0.01).abs() < 1e-12);
    assert!(
        (corrected[0] - seed[0] - x[0]).abs() < 1e-12
            && (corrected[1] - seed[1] - x[1]).abs() < 1e-12
    );
    assert_eq!(PositionUpdate::default(), PositionUpdate::Corrected);
}

#[test]
fn wall_ahead_triggers_reverse_turn_and_replan_with_hysteresis() {
    let mut rig = Rig::new();
    let open = scan_uniform(180, 4.0, 4.0);
    // Cruise up to 0.4 m/s in the open.
    for _ in 0..50 {
        rig.step(Some(&open), None);
    }
    assert!((rig.last.v - 0.4).abs() < 1e-9 && rig.bb().bounces() == 0);
    // A wall 0.1 m (d_obs) ahead: below d_th = 0.15.
    let close = scan_wall_ahead(180, 0.2 + 0.1, 4.0);
    let band = scan_wall_ahead(180, 0.2 + 0.25, 4.0);
    let c = rig.step(Some(&close), None);
    assert_eq!((rig.bb().bounces(), c.mode), (1, MODE_BOUNCE_BACK));
    assert!(
        matches!(rig.bb().phase(), Phase::Reversing { v_rev, .. } if (v_rev + 0.2).abs() < 1e-12)
    );
    // It reverses: −α·v = −0.2 m/s, reached within the acceleration limit (0.6 m/s at 2 m/s²).
    let mut min_v = f64::INFINITY;
    let mut steps = 0;
    while matches!(
        rig.bb().phase(),
        Phase::Reversing { .. } | Phase::Turning { .. }
    ) && steps < 1000
    {
        let c = rig.step(Some(&band), None);
        let handed_back = matches!(rig.bb().phase(), Phase::Disarmed { .. });
        assert_eq!(
            c.mode,
            if handed_back {
                MODE_EXPLORE
            } else {
                MODE_BOUNCE_BACK
            }
        );
        min_v = min_v.min(c.v);
        steps += 1;
    }
    assert!((min_v + 0.2).abs() < 1e-9, "{min_v}");
    assert!(
        matches!(rig.bb().phase(), Phase::Disarmed { .. }),
        "{:?}",
        rig.bb().phase()
    );
    // Turned toward the freest direction: away from the wall (it was ahead, at θ = 0).
    assert!(rig.pose.theta.abs() > PI - 0.2, "{}", rig.pose.theta);
    assert_eq!(rig.bb().inner().replans, 1);
    // d_obs stays in [d_th, d_release] for 10 s, longer than the cooldown: no re-trigger.
    for _ in 0..1000 {
        let c = rig.step(Some(&band), None);
        assert_eq!(c.mode, MODE_EXPLORE);
    }
    assert_eq!(rig.bb().bounces(), 1);
    // Clear (d_obs > d_release), then close again: re-armed, it triggers.
    rig.step(Some(&open), None);
    assert_eq!(rig.bb().phase(), Phase::Armed);
    rig.step(Some(&close), None);
    assert_eq!(rig.bb().bounces(), 2);
}

#[test]
fn without_a_release_the_cooldown_re_arms() {
    let mut rig = Rig::new();
    let close = scan_wall_ahead(180, 0.2 + 0.1, 4.0);
    // Standing, the range trigger waits (turning in place cannot hit anything)...
    let pose = Pose2::new(1.0, 1.0, 0.0);
    let mut standing = PlannerInput {
        tick: 0,
        dt: DT,
        pose,
        scan: Some(&close),
        tactile: None,
        grid: None,
        last_command: Command::STOP,
    };
    let mut stand = forward_stack();
    standing.last_command = stand.step(&standing);
    assert_eq!(stand.bounces(), 0);
    // ...until the robot moves.
    standing.tick = 1;
    stand.step(&standing);
    assert_eq!(stand.bounces(), 1);
    for _ in 0..50 {
        rig.step(None, None);
    }
    rig.step(Some(&close), None);
    assert_eq!(rig.bb().bounces(), 1);
    // The wall stays 0.1 m ahead whatever the robot does (a sensor glitch or a pushed robot):
    // it bounces again only after each cooldown, never every step.
    for _ in 0..1500 {
        rig.step(Some(&close), None);
    }
    let b = rig.bb().bounces();
    // 15 s: each cycle is ≤ 0.8 s reversing + a turn (π at ≤ 2 rad/s ≈ 1.6 s) + 3 s cooldown.
    assert!((2..=5).contains(&b), "{b}");
}

#[test]
fn tactile_contact_triggers_and_backs_away_from_the_touched_side() {
    let mut rig = Rig::new();
    for _ in 0..50 {
        rig.step(None, None);
    }
    let mut t: Box<Tactile> = bytemuck::zeroed_box();
    t.n_sensors = 8;
    t.radius = 0.2;
    // Sensor 0 (front) is pushed backwards: the obstacle is ahead.
    t.sensors[0].fx = -5.0;
    let c = rig.step(None, Some(&t));
    assert_eq!((rig.bb().bounces(), c.mode), (1, MODE_BOUNCE_BACK));
    assert!(
        matches!(rig.bb().phase(), Phase::Reversing { v_rev, target, .. } if v_rev < 0.0 && target.abs() > 3.0)
    );
    // A touch below the threshold (noise) does not trigger.
    let mut rig = Rig::new();
    t.sensors[0].fx = -0.3;
    rig.step(None, Some(&t));
    assert_eq!(rig.bb().bounces(), 0);
    // From standstill, touched from behind (pushed forward): back away forward.
    let mut rig = Rig::new();
    t.sensors[0].fx = 0.0;
    t.sensors[4].angle = PI as f32;
    t.sensors[4].fx = 5.0;
    rig.step(None, Some(&t));
    assert!(
        matches!(rig.bb().phase(), Phase::Reversing { v_rev, .. } if (v_rev - 0.1).abs() < 1e-12)
    );
}

#[test]
fn speed_is_capped_so_the_robot_can_stop_before_the_wall() {
    let mut rig = Rig::new();
    let open = scan_uniform(180, 4.0, 4.0);
    for _ in 0..50 {
        rig.step(Some(&open), None);
    }
    // 0.17 m ahead (just above d_th): cap √(2·2·(0.17 − 0.05)) ≈ 0.69 > 0.4, no effect.
    let c = rig.step(Some(&scan_wall_ahead(180, 0.37, 4.0)), None);
    assert!((c.v - 0.4).abs() < 1e-9);
    // Disarmed after a bounce (no range trigger), a wall 0.14 m (d_obs) ahead, below d_th: the
    // cap brakes the robot to a stop about d_stop short of it; held there while the wrapped
    // planner presses on, it bounces instead of waiting for the cooldown.
    rig.stack.inner_mut().phase = Phase::Disarmed { since: rig.tick };
    let wall_x = rig.pose.x + 0.2 + 0.14;
    let mut closest = f64::INFINITY;
    let mut stopped_before_bounce = false;
    for _ in 0..100 {
        let scan = scan_wall_ahead(180, wall_x - rig.pose.x, 4.0);
        rig.step(Some(&scan), None);
        closest = closest.min(wall_x - rig.pose.x - 0.2);
        if rig.bb().bounces() == 0 && rig.last.v.abs() < 0.05 {
            stopped_before_bounce = true;
        }
    }
    assert!(stopped_before_bounce);
    assert!(closest > 0.03 && closest < 0.06, "{closest}");
    assert_eq!(rig.bb().bounces(), 1);
}

#[test]
fn non_finite_pose_stops_and_never_outputs_nan() {
    let mut rig = Rig::new();
    for _ in 0..50 {
        rig.step(None, None);
    }
    rig.pose = Pose2::new(f64::NAN, 0.0, f64::INFINITY);
    for _ in 0..30 {
        let c = rig.step(None, None);
        assert!(c.v.is_finite() && c.omega.is_finite() && c.mode == MODE_IDLE);
        rig.pose = Pose2::new(f64::NAN, 0.0, f64::INFINITY);
    }
    assert_eq!(rig.last.v, 0.0);
}

#[test]
fn random_walk_inside_bounce_back_reports_its_bounces_through_the_trait() {
    let mut p: Box<dyn Planner> = Box::new(Limited::new(
        BounceBack::new(
            RandomWalk::new(limits(), RandomWalkConfig::default(), 1),
            limits(),
            BounceBackConfig::default(),
        ),
        limits(),
    ));
    let mut t: Box<Tactile> = bytemuck::zeroed_box();
    t.n_sensors = 1;
    t.sensors[0].fx = -2.0;
    let input = PlannerInput {
        tick: 0,
        dt: DT,
        pose: Pose2::new(1.0, 1.0, 0.0),
        scan: None,
        tactile: Some(&t),
        grid: None,
        last_command: Command::STOP,
    };
    let c = p.step(&input);
    assert_eq!(
        (p.bounces(), c.mode, p.kind()),
        (1, MODE_BOUNCE_BACK, PlannerKind::RandomWalk)
    );
}

#[test]
fn bad_config_is_sanitized() {
    let c = BounceBackConfig {
        d_th: Some(0.5),
        d_release: Some(0.2),
        alpha: 7.0,
        cooldown: f64::NAN,
        ..Default::default()
    }
    .sanitized();
    assert!(c.d_release() > c.d_th());
    assert_eq!(c.alpha, 1.0);
    assert_eq!(c.cooldown, BounceBackConfig::default().cooldown);
}

proptest::proptest! {
    /// Whatever the sensors say (NaN, negative or huge ranges and forces, bad poses), the stack
    /// answers with finite commands inside the speed and acceleration limits.
    #[test]
    fn commands_stay_finite_and_limited_on_any_input(
        steps in proptest::collection::vec(
            (
                proptest::collection::vec(proptest::prop_oneof![
                    Just(f32::NAN), Just(-1.0f32), 0.0f32..5.0, Just(f32::INFINITY)
                ], 0..64),
                proptest::prop_oneof![Just(f32::NAN), -50.0f32..50.0],
                proptest::prop_oneof![Just(f64::NAN), Just(f64::INFINITY), -10.0f64..10.0],
                0u64..3,
            ),
            1..80,
        ),
        seed in 0u64..1000,
    ) {
        let l = limits();
        let walk = RandomWalk::new(l, RandomWalkConfig::default(), seed);
        let mut p = Limited::new(BounceBack::new(walk, l, BounceBackConfig::default()), l);
        let mut prev = Command::STOP;
        let mut scan: Box<Scan> = bytemuck::zeroed_box();
        let mut tactile: Box<Tactile> = bytemuck::zeroed_box();
        let mut tick = 0;
        for (ranges, force, coord, dtick) in steps {
            scan.n_beams = ranges.len() as u32;
            scan.angle_min = -3.0;
            scan.angle_increment = 0.1;
            scan.range_max = 4.0;
            scan.ranges[..ranges.len()].copy_from_slice(&ranges);
            tactile.n_sensors = 2;
            tactile.sensors[1].fx = force;
            tick += dtick;
            let input = PlannerInput {
                tick,
                dt: DT,
                pose: Pose2::new(coord, 1.0, coord * 0.3),
                scan: Some(&scan),
                tactile: Some(&tactile),
                grid: None,
                last_command: prev,
            };
            let c = p.step(&input);
            proptest::prop_assert!(c.v.is_finite() && c.omega.is_finite());
            proptest::prop_assert!(c.v.abs() <= l.max_speed && c.omega.abs() <= l.max_omega);
            proptest::prop_assert!((c.v - prev.v).abs() <= l.max_accel * DT + 1e-12);
            proptest::prop_assert!((c.omega - prev.omega).abs() <= l.max_alpha * DT + 1e-12);
            prev = c;
        }
    }
}
