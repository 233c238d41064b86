//! Tests of [`Sensing`]: exact geometry with zero noise, noise statistics, determinism, tactile
//! attribution, beacon visibility and the fix period.

use super::*;
use approx::assert_relative_eq;
use core::f64::consts::{FRAC_PI_2, FRAC_PI_4, FRAC_PI_8, PI, SQRT_2};
use mole_types::{Contact, Header, MAX_OBSTACLES, Square};

/// A 10 m × 10 m arena, noiseless sensors, a full-circle 360-beam lidar and 8 tactile sensors.
fn map() -> Box<WorldMap> {
    let mut m: Box<WorldMap> = bytemuck::zeroed_box();
    m.arena_width = 10.0;
    m.arena_height = 10.0;
    m.dt = 0.01;
    m.grid_resolution = 0.05;
    m.robot.radius = 0.2;
    m.sensors = SensorSpec {
        lidar_beams: 360,
        tactile_sensors: 8,
        lidar_range_max: 20.0,
        lidar_fov: TAU,
        tactile_stiffness: 1000.0,
        beacon_range_max: 8.0,
        ..SensorSpec::default()
    };
    m
}

fn with_squares(mut m: Box<WorldMap>, squares: &[Square]) -> Box<WorldMap> {
    m.obstacles[..squares.len()].copy_from_slice(squares);
    m.n_obstacles = squares.len() as u32;
    m
}

fn truth(x: f64, y: f64, theta: f64) -> Box<Truth> {
    let mut t: Box<Truth> = bytemuck::zeroed_box();
    t.x = x;
    t.y = y;
    t.theta = theta;
    t
}

fn sensing(m: &WorldMap) -> Sensing {
    Sensing::new(m, 42).expect("valid map")
}

/// Sample mean and standard deviation.
fn mean_std(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    (mean, var.sqrt())
}

/// Mean within 4 standard errors of 0 and std within `rel` of σ.
fn assert_gaussian(residuals: &[f64], sigma: f64, rel: f64) {
    let (mean, std) = mean_std(residuals);
    let n = residuals.len() as f64;
    assert!(
        mean.abs() < 4.0 * sigma / n.sqrt(),
        "mean {mean} (σ {sigma}, n {n})"
    );
    assert!(
        (std / sigma - 1.0).abs() < rel,
        "std {std} vs σ {sigma} (n {n})"
    );
}

// ---------------------------------------------------------------------------------------------
// lidar
// ---------------------------------------------------------------------------------------------

#[test]
fn full_circle_scan_reads_the_walls_exactly() {
    let mut s = sensing(&map());
    let mut scan: Box<Scan> = bytemuck::zeroed_box();
    scan.header.seq = 7;
    s.scan(&truth(5.0, 5.0, 0.0), &mut scan);
    assert_eq!(scan.header.seq, 7, "the header belongs to the caller");
    assert_eq!(scan.n_beams, 360);
    assert_eq!(scan.angle_min, -PI as f32);
    assert_relative_eq!(scan.angle_increment, (TAU / 360.0) as f32);
    assert_eq!(scan.range_max, 20.0);
    let r = scan.ranges();
    // Beam 0 looks back (−π), 90 right (−π/2), 180 ahead, 225 at +π/4 (to the corner).
    assert_relative_eq!(r[0], 5.0, epsilon = 1e-5);
    assert_relative_eq!(r[90], 5.0, epsilon = 1e-5);
    assert_relative_eq!(r[180], 5.0, epsilon = 1e-5);
    assert_relative_eq!(r[225], (5.0 * SQRT_2) as f32, epsilon = 1e-5);
    assert!(scan.ranges[360..].iter().all(|&x| x == 0.0));

    // Heading +y from (5, 2): ahead is 8 m, behind 2 m.
    s.scan(&truth(5.0, 2.0, FRAC_PI_2), &mut scan);
    assert_relative_eq!(scan.ranges[180], 8.0, epsilon = 1e-5);
    assert_relative_eq!(scan.ranges[0], 2.0, epsilon = 1e-5);
}

#[test]
fn partial_fov_puts_end_beams_on_its_edges() {
    let mut m = map();
    m.sensors.lidar_beams = 181;
    m.sensors.lidar_fov = PI;
    let mut s = sensing(&m);
    let mut scan: Box<Scan> = bytemuck::zeroed_box();
    s.scan(&truth(3.0, 4.0, 0.0), &mut scan);
    assert_eq!(scan.n_beams, 181);
    assert_eq!(scan.angle_min, -FRAC_PI_2 as f32);
    assert_relative_eq!(scan.angle_increment, (PI / 180.0) as f32);
    assert_relative_eq!(scan.ranges[0], 4.0, epsilon = 1e-5); // −π/2: wall y = 0
    assert_relative_eq!(scan.ranges[90], 7.0, epsilon = 1e-5); // ahead: wall x = 10
    assert_relative_eq!(scan.ranges[180], 6.0, epsilon = 1e-5); // +π/2: wall y = 10

    // A single beam of a partial fov looks straight ahead.
    let layout = BeamLayout::new(1, PI, 10.0);
    assert_eq!((layout.angle_min, layout.angle_increment), (0.0, 0.0));
    // A fov a hair above 2π is a full circle.
    let layout = BeamLayout::new(4, TAU + 1e-9, 10.0);
    assert_relative_eq!(layout.angle_increment, FRAC_PI_2);
    assert_relative_eq!(layout.angle_min, -PI);
}

#[test]
fn square_in_front_and_range_limit() {
    let m = with_squares(map(), &[Square::new(5.0, 5.0, 2.0)]);
    let mut s = sensing(&m);
    let mut scan: Box<Scan> = bytemuck::zeroed_box();
    s.scan(&truth(2.0, 5.0, 0.0), &mut scan);
    assert_relative_eq!(scan.ranges[180], 2.0, epsilon = 1e-6);
    assert_relative_eq!(scan.ranges[0], 2.0, epsilon = 1e-6);

    // Range max 1.5: nothing within range, every beam reads exactly range_max, even with noise.
    let mut m = with_squares(map(), &[Square::new(5.0, 5.0, 2.0)]);
    m.sensors.lidar_range_max = 1.5;
    m.sensors.lidar_range_std = 0.5;
    let mut s = sensing(&m);
    s.scan(&truth(2.0, 5.0, 0.0), &mut scan);
    assert_eq!(scan.range_max, 1.5);
    assert!(scan.ranges().iter().all(|&r| r == 1.5));
}

#[test]
fn lidar_noise_has_the_configured_statistics_and_stays_clamped() {
    let sigma = 0.05;
    let mut m = with_squares(map(), &[Square::new(7.0, 5.0, 1.0)]);
    m.sensors.lidar_range_std = sigma;
    let mut s = sensing(&m);
    let t = truth(5.0, 5.0, 0.3);
    let mut scan: Box<Scan> = bytemuck::zeroed_box();
    let layout = *s.beam_layout();
    let exact: Vec<f64> = (0..360)
        .map(|i| {
            s.ray_caster()
                .cast(t.x, t.y, t.theta + layout.angle(i), 20.0)
        })
        .collect();
    let mut residuals = Vec::new();
    for _ in 0..40 {
        s.scan(&t, &mut scan);
        for (r, e) in scan.ranges().iter().zip(&exact) {
            residuals.push(*r as f64 - e);
        }
    }
    assert_gaussian(&residuals, sigma, 0.03);

    // Huge noise near a close wall: readings stay within [0, range_max].
    let mut m = map();
    m.sensors.lidar_range_std = 3.0;
    m.sensors.lidar_range_max = 6.0;
    let mut s = sensing(&m);
    for _ in 0..20 {
        s.scan(&truth(0.5, 5.0, 0.0), &mut scan);
        assert!(scan.ranges().iter().all(|&r| (0.0..=6.0).contains(&r)));
        assert!(scan.ranges().contains(&0.0), "clamping at 0 happens");
    }
}

#[test]
fn no_lidar_gives_an_empty_scan() {
    let mut m = map();
    m.sensors.lidar_beams = 0;
    m.sensors.lidar_fov = 0.0;
    let mut s = sensing(&m);
    let mut scan: Box<Scan> = bytemuck::zeroed_box();
    scan.ranges[3] = 9.0;
    s.scan(&truth(5.0, 5.0, 0.0), &mut scan);
    assert_eq!(scan.n_beams, 0);
    assert!(scan.ranges.iter().all(|&r| r == 0.0));
    assert_eq!(scan.validate(), Ok(()));
}

// ---------------------------------------------------------------------------------------------
// tactile
// ---------------------------------------------------------------------------------------------

/// A contact on the rim at robot-frame direction `phi`, pushing the robot back towards its centre.
fn rim_contact(t: &Truth, radius: f64, phi: f64, depth: f64) -> Contact {
    let a = t.theta + phi;
    let (s, c) = a.sin_cos();
    Contact {
        px: t.x + radius * c,
        py: t.y + radius * s,
        nx: -c,
        ny: -s,
        depth,
    }
}

fn tactile_of(s: &mut Sensing, t: &Truth) -> Box<Tactile> {
    let mut out: Box<Tactile> = bytemuck::zeroed_box();
    s.tactile(t, &mut out);
    out
}

#[test]
fn contact_straight_ahead_lands_on_sensor_zero() {
    let mut s = sensing(&map());
    let mut t = truth(5.0, 5.0, 0.7);
    t.contacts[0] = rim_contact(&t, 0.2, 0.0, 0.01);
    t.n_contacts = 1;
    let out = tactile_of(&mut s, &t);
    assert_eq!(out.n_sensors, 8);
    assert_eq!(out.radius, 0.2);
    // stiffness 1000 N/m × 0.01 m = 10 N, pushing the robot backwards: (−10, 0) in its frame.
    assert_relative_eq!(out.sensors[0].fx, -10.0, epsilon = 1e-4);
    assert_relative_eq!(out.sensors[0].fy, 0.0, epsilon = 1e-4);
    for r in &out.sensors()[1..] {
        assert_eq!((r.fx, r.fy), (0.0, 0.0));
    }
    for (i, r) in out.sensors().iter().enumerate() {
        assert_relative_eq!(r.angle, (TAU * i as f64 / 8.0) as f32);
    }
}

#[test]
fn contact_between_two_sensors_splits_and_keeps_the_magnitude() {
    let mut s = sensing(&map());
    let mut t = truth(5.0, 5.0, -2.0);
    t.contacts[0] = rim_contact(&t, 0.2, FRAC_PI_8, 0.02);
    t.n_contacts = 1;
    let out = tactile_of(&mut s, &t);
    let half = (-10.0 * FRAC_PI_8.cos(), -10.0 * FRAC_PI_8.sin());
    for i in [0, 1] {
        assert_relative_eq!(out.sensors[i].fx as f64, half.0, epsilon = 1e-4);
        assert_relative_eq!(out.sensors[i].fy as f64, half.1, epsilon = 1e-4);
    }
    let (fx, fy) = out
        .sensors()
        .iter()
        .fold((0.0, 0.0), |(x, y), r| (x + r.fx as f64, y + r.fy as f64));
    assert_relative_eq!(fx.hypot(fy), 1000.0 * 0.02, epsilon = 1e-4);
    assert!(
        out.sensors()[2..]
            .iter()
            .all(|r| r.fx == 0.0 && r.fy == 0.0)
    );

    // Two contacts: ahead-left at 3π/4 (sensor 3, 75 %; sensor 4, 25 %) and behind-right.
    let mut t = truth(5.0, 5.0, 0.0);
    t.contacts[0] = rim_contact(&t, 0.2, 3.0 * FRAC_PI_4 + FRAC_PI_4 / 4.0, 0.01);
    t.contacts[1] = rim_contact(&t, 0.2, -FRAC_PI_2, 0.005);
    t.n_contacts = 2;
    let out = tactile_of(&mut s, &t);
    let m3 = (out.sensors[3].fx as f64).hypot(out.sensors[3].fy as f64);
    let m4 = (out.sensors[4].fx as f64).hypot(out.sensors[4].fy as f64);
    assert_relative_eq!(m3, 7.5, epsilon = 1e-4);
    assert_relative_eq!(m4, 2.5, epsilon = 1e-4);
    // −π/2 is sensor 6 (at 3π/2); the force points +y in the robot frame.
    assert_relative_eq!(out.sensors[6].fy, 5.0, epsilon = 1e-4);
    for i in [0, 1, 2, 5, 7] {
        assert_eq!(
            (out.sensors[i].fx, out.sensors[i].fy),
            (0.0, 0.0),
            "sensor {i}"
        );
    }
}

#[test]
fn idle_sensors_read_exactly_zero_even_with_noise() {
    let mut m = map();
    m.sensors.tactile_force_std = 0.5;
    let mut s = sensing(&m);
    // No contacts at all.
    let t = truth(5.0, 5.0, 1.0);
    for _ in 0..10 {
        let out = tactile_of(&mut s, &t);
        assert!(out.sensors().iter().all(|r| r.fx == 0.0 && r.fy == 0.0));
        assert_eq!(out.validate(), Ok(()));
    }
    // One contact on sensor 2: only sensor 2 is noisy.
    let mut t = truth(5.0, 5.0, 1.0);
    t.contacts[0] = rim_contact(&t, 0.2, FRAC_PI_2, 0.01);
    t.n_contacts = 1;
    let mut residuals = Vec::new();
    for _ in 0..2000 {
        let out = tactile_of(&mut s, &t);
        for (i, r) in out.sensors().iter().enumerate() {
            if i != 2 {
                assert_eq!((r.fx, r.fy), (0.0, 0.0));
            }
        }
        residuals.push(out.sensors[2].fx as f64);
        residuals.push(out.sensors[2].fy as f64 + 10.0);
    }
    assert_gaussian(&residuals, 0.5, 0.05);
}

#[test]
fn zero_depth_and_degenerate_contacts_carry_no_force() {
    let mut m = map();
    m.sensors.tactile_force_std = 0.5;
    let mut s = sensing(&m);
    let mut t = truth(5.0, 5.0, 0.0);
    t.contacts[0] = rim_contact(&t, 0.2, 0.0, 0.0);
    t.contacts[1] = Contact {
        nx: 0.0,
        ny: 0.0,
        ..rim_contact(&t, 0.2, 1.0, 0.01)
    };
    t.contacts[2] = Contact {
        depth: f64::NAN,
        ..rim_contact(&t, 0.2, 2.0, 0.01)
    };
    t.n_contacts = 3;
    let out = tactile_of(&mut s, &t);
    assert!(out.sensors().iter().all(|r| r.fx == 0.0 && r.fy == 0.0));
    // A contact point at the centre falls back on the normal's direction.
    let mut t = truth(5.0, 5.0, 0.0);
    t.contacts[0] = Contact {
        px: 5.0,
        py: 5.0,
        nx: 0.0,
        ny: -1.0,
        depth: 0.01,
    };
    t.n_contacts = 1;
    m.sensors.tactile_force_std = 0.0;
    let mut s = sensing(&m);
    let out = tactile_of(&mut s, &t);
    assert_relative_eq!(out.sensors[2].fy, -10.0, epsilon = 1e-4);
}

// ---------------------------------------------------------------------------------------------
// odometry and fix
// ---------------------------------------------------------------------------------------------

#[test]
fn odometry_is_the_applied_velocity_plus_noise() {
    let mut m = map();
    let mut s = sensing(&m);
    let mut t = truth(5.0, 5.0, 0.0);
    t.v = 0.4;
    t.omega = -0.3;
    let mut out: Odom = bytemuck::Zeroable::zeroed();
    s.odom(&t, &mut out);
    assert_eq!((out.v, out.omega, out.dt), (0.4, -0.3, 0.01));

    m.sensors.odom_v_std = 0.1;
    m.sensors.odom_omega_std = 0.05;
    let mut s = sensing(&m);
    let (mut dv, mut dw) = (Vec::new(), Vec::new());
    for _ in 0..5000 {
        s.odom(&t, &mut out);
        dv.push(out.v - 0.4);
        dw.push(out.omega + 0.3);
    }
    assert_gaussian(&dv, 0.1, 0.05);
    assert_gaussian(&dw, 0.05, 0.05);
}

/// The odometry pose integrates the measured velocities in the odom frame; over steps sensing
/// did not see, it follows the truth's motion between the two it saw (noise-free here), so a
/// reader that missed messages loses nothing; a restart goes on from the pose it resumes.
#[test]
fn odometry_integrates_and_covers_the_steps_it_did_not_see() {
    let m = map();
    let mut s = sensing(&m);
    let mut t = truth(5.0, 5.0, 0.0);
    (t.v, t.omega) = (0.5, 0.0);
    let mut out: Odom = bytemuck::Zeroable::zeroed();
    for tick in 0..10 {
        t.header.tick = tick;
        s.odom(&t, &mut out);
    }
    assert_relative_eq!(out.x, 0.05, epsilon = 1e-12);
    assert_eq!((out.y, out.theta, out.dt), (0.0, 0.0, 0.01));
    // 40 steps unseen: the robot went on to (5.5, 5.2), turning by 0.8 rad along one arc.
    let before = Pose2::new(t.x, t.y, t.theta);
    let there = mole_types::unicycle_arc(before, 0.6, 0.8, 1.0);
    (t.x, t.y, t.theta, t.header.tick) = (there.x, there.y, there.theta, 49);
    s.odom(&t, &mut out);
    assert_relative_eq!(out.dt, 0.4, epsilon = 1e-12);
    assert_relative_eq!(out.v * out.dt, 0.6, epsilon = 1e-9);
    assert_relative_eq!(out.omega * out.dt, 0.8, epsilon = 1e-9);
    let expected = mole_types::unicycle_arc(Pose2::new(0.05, 0.0, 0.0), 0.6, 0.8, 1.0);
    assert_relative_eq!(out.x, expected.x, epsilon = 1e-9);
    assert_relative_eq!(out.y, expected.y, epsilon = 1e-9);
    assert_relative_eq!(out.theta, expected.theta, epsilon = 1e-9);
    // A restart resumes the odom frame; over the 11 steps since the odometry it resumed (tick
    // 49), it holds the velocities it measures now.
    let mut restarted = sensing(&m);
    out.header.tick = 49;
    restarted.resume_odometry(&out);
    let mut next: Odom = bytemuck::Zeroable::zeroed();
    t.header.tick = 60;
    restarted.odom(&t, &mut next);
    let held = mole_types::unicycle_arc(expected, 0.5, 0.0, 0.11);
    assert_relative_eq!(next.x, held.x, epsilon = 1e-9);
    assert_relative_eq!(next.y, held.y, epsilon = 1e-9);
    assert_relative_eq!(next.dt, 0.11, epsilon = 1e-12);
}

#[test]
fn fix_is_valid_on_its_period_only() {
    let mut m = map();
    m.sensors.fix_period_ticks = 5;
    let mut s = sensing(&m);
    let mut t = truth(3.0, 4.0, 0.0);
    let mut out: Fix = bytemuck::Zeroable::zeroed();
    let mut valid_ticks = Vec::new();
    for tick in 0..12 {
        t.header = Header {
            tick,
            ..Header::default()
        };
        s.fix(&t, &mut out);
        assert_eq!(out.validate(), Ok(()));
        if out.valid == 1 {
            valid_ticks.push(tick);
            assert_eq!((out.x, out.y), (3.0, 4.0));
        } else {
            assert_eq!((out.x, out.y), (0.0, 0.0));
        }
    }
    assert_eq!(valid_ticks, [0, 5, 10]);

    m.sensors.fix_period_ticks = 0;
    let mut s = sensing(&m);
    for tick in 0..12 {
        t.header.tick = tick;
        s.fix(&t, &mut out);
        assert_eq!(out.valid, 0);
    }

    m.sensors.fix_period_ticks = 1;
    m.sensors.fix_std = 0.3;
    let mut s = sensing(&m);
    let mut residuals = Vec::new();
    for _ in 0..3000 {
        s.fix(&t, &mut out);
        assert_eq!((out.valid, out.std), (1, 0.3));
        residuals.push(out.x - 3.0);
        residuals.push(out.y - 4.0);
    }
    assert_gaussian(&residuals, 0.3, 0.05);
}

// ---------------------------------------------------------------------------------------------
// beacons
// ---------------------------------------------------------------------------------------------

fn beacon_map() -> Box<WorldMap> {
    let mut m = with_squares(map(), &[Square::new(5.0, 5.0, 2.0)]);
    let sites = [(8.0, 5.0), (2.0, 8.0), (2.0, 9.9), (5.0, 7.0), (4.0, 5.0)];
    m.place_beacons(&sites);
    m.sensors.beacon_range_max = 4.0;
    m
}

#[test]
fn beacons_behind_a_square_or_out_of_range_are_not_seen() {
    let m = beacon_map();
    let mut s = sensing(&m);
    let mut out: Box<Beacons> = bytemuck::zeroed_box();
    s.beacons(&truth(2.0, 5.0, PI), &mut out);
    assert_eq!(out.validate(), Ok(()));
    let r = out.readings();
    // 0 is behind the square, 2 is 4.9 m away; 4 sits on the square's face and is seen.
    let ids: Vec<u32> = r.iter().map(|b| b.id).collect();
    assert_eq!(ids, [1, 3, 4]);
    assert_relative_eq!(r[0].range, 3.0, epsilon = 1e-12);
    assert_relative_eq!(r[0].bearing, -FRAC_PI_2, epsilon = 1e-12); // left of the world, heading −x
    assert_relative_eq!(r[1].range, 13f64.sqrt(), epsilon = 1e-12);
    assert_relative_eq!(r[1].bearing, (2.0f64).atan2(3.0) - PI, epsilon = 1e-12);
    assert_relative_eq!(r[2].range, 2.0, epsilon = 1e-12);
    assert_relative_eq!(r[2].bearing, PI, epsilon = 1e-12);
    assert!(
        out.readings[3..]
            .iter()
            .all(|b| *b == BeaconReading::default())
    );

    // Seen over the square from higher up, once within range.
    let mut m = beacon_map();
    m.sensors.beacon_range_max = 8.0;
    let mut s = sensing(&m);
    s.beacons(&truth(2.0, 9.0, 0.0), &mut out);
    let seen = out
        .readings()
        .iter()
        .find(|b| b.id == 0)
        .expect("beacon 0 seen");
    assert_relative_eq!(seen.range, 52f64.sqrt(), epsilon = 1e-12);
    assert_relative_eq!(seen.bearing, (-4.0f64).atan2(6.0), epsilon = 1e-12);
    // Still hidden from just above the square's corner line.
    s.beacons(&truth(2.0, 7.5, 0.0), &mut out);
    assert!(out.readings().iter().all(|b| b.id != 0));
}

/// With `beacons_anonymous` set, the same beacons are seen with the same ranges and bearings,
/// but every reading's id is `LANDMARK_ANONYMOUS`; a switch value other than 0 or 1 is refused.
#[test]
fn anonymous_beacons_hide_their_ids() {
    let t = truth(2.0, 5.0, PI);
    let mut named: Box<Beacons> = bytemuck::zeroed_box();
    sensing(&beacon_map()).beacons(&t, &mut named);
    let mut m = beacon_map();
    m.sensors.beacons_anonymous = 1;
    let mut anonymous: Box<Beacons> = bytemuck::zeroed_box();
    sensing(&m).beacons(&t, &mut anonymous);
    assert_eq!(anonymous.validate(), Ok(()));
    assert_eq!(anonymous.n_readings, 3);
    for (a, b) in anonymous.readings().iter().zip(named.readings()) {
        assert_eq!(a.id, mole_types::LANDMARK_ANONYMOUS);
        assert_eq!((a.range, a.bearing), (b.range, b.bearing));
    }
    m.sensors.beacons_anonymous = 2;
    assert_eq!(
        Sensing::new(&m, 42).unwrap_err(),
        SensingError::InvalidMap(Invalid::UnknownCode("sensors.beacons_anonymous"))
    );
}

#[test]
fn beacon_noise_keeps_ranges_non_negative_and_bearings_wrapped() {
    let mut m = beacon_map();
    m.sensors.beacon_range_std = 2.0;
    m.sensors.beacon_bearing_std = 1.0;
    let mut s = sensing(&m);
    let mut out: Box<Beacons> = bytemuck::zeroed_box();
    let t = truth(2.0, 5.0, PI);
    let mut residuals = Vec::new();
    for _ in 0..2000 {
        s.beacons(&t, &mut out);
        assert_eq!(out.n_readings, 3);
        for b in out.readings() {
            assert!(b.range >= 0.0);
            assert!(b.bearing > -PI && b.bearing <= PI);
        }
        residuals.push(wrap_angle(out.readings[2].bearing - PI));
    }
    // Bearing noise is wrapped, so test its centre only, with a small σ below.
    assert!(mean_std(&residuals).0.abs() < 0.15);
    m.sensors.beacon_range_std = 0.02;
    m.sensors.beacon_bearing_std = 0.01;
    let mut s = sensing(&m);
    let (mut dr, mut db) = (Vec::new(), Vec::new());
    for _ in 0..3000 {
        s.beacons(&t, &mut out);
        dr.push(out.readings[0].range - 3.0);
        db.push(out.readings[0].bearing + FRAC_PI_2);
    }
    assert_gaussian(&dr, 0.02, 0.05);
    assert_gaussian(&db, 0.01, 0.05);
}

// ---------------------------------------------------------------------------------------------
// determinism and construction
// ---------------------------------------------------------------------------------------------

fn noisy_map() -> Box<WorldMap> {
    let mut m = beacon_map();
    let s = &mut m.sensors;
    s.lidar_range_std = 0.05;
    s.tactile_force_std = 0.2;
    s.odom_v_std = 0.01;
    s.odom_omega_std = 0.02;
    s.beacon_range_std = 0.1;
    s.beacon_bearing_std = 0.05;
    s.fix_std = 0.3;
    s.fix_period_ticks = 2;
    m
}

/// Runs every sensor for a few ticks and returns the outputs' bytes.
fn run(s: &mut Sensing) -> Vec<u8> {
    let mut bytes = Vec::new();
    let mut scan: Box<Scan> = bytemuck::zeroed_box();
    let mut tac: Box<Tactile> = bytemuck::zeroed_box();
    let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
    let mut odom: Odom = bytemuck::Zeroable::zeroed();
    let mut fix: Fix = bytemuck::Zeroable::zeroed();
    for tick in 0..5u64 {
        let mut t = truth(2.0, 5.0 + 0.1 * tick as f64, 0.2 * tick as f64);
        t.header.tick = tick;
        t.v = 0.3;
        t.contacts[0] = rim_contact(&t, 0.2, 0.3, 0.01);
        t.n_contacts = 1;
        s.scan(&t, &mut scan);
        s.tactile(&t, &mut tac);
        s.odom(&t, &mut odom);
        s.beacons(&t, &mut beacons);
        s.fix(&t, &mut fix);
        bytes.extend_from_slice(bytemuck::bytes_of(&*scan));
        bytes.extend_from_slice(bytemuck::bytes_of(&*tac));
        bytes.extend_from_slice(bytemuck::bytes_of(&odom));
        bytes.extend_from_slice(bytemuck::bytes_of(&*beacons));
        bytes.extend_from_slice(bytemuck::bytes_of(&fix));
    }
    bytes
}

#[test]
fn same_seed_same_outputs_different_seed_different_outputs() {
    let m = noisy_map();
    let a = run(&mut Sensing::new(&m, 7).expect("valid"));
    let b = run(&mut Sensing::new(&m, 7).expect("valid"));
    let c = run(&mut Sensing::new(&m, 8).expect("valid"));
    assert!(a == b, "same seed, same bytes");
    assert!(a != c, "different seed, different bytes");
}

#[test]
fn a_sensor_does_not_depend_on_the_others_being_called() {
    let m = noisy_map();
    let mut all = Sensing::new(&m, 3).expect("valid");
    let mut odom_only = Sensing::new(&m, 3).expect("valid");
    let t = truth(2.0, 5.0, 0.0);
    let mut scan: Box<Scan> = bytemuck::zeroed_box();
    let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
    let (mut o1, mut o2): (Odom, Odom) =
        (bytemuck::Zeroable::zeroed(), bytemuck::Zeroable::zeroed());
    for _ in 0..3 {
        all.beacons(&t, &mut beacons);
        all.scan(&t, &mut scan);
        all.odom(&t, &mut o1);
        odom_only.odom(&t, &mut o2);
        assert_eq!(o1, o2);
    }
}

#[test]
fn inconsistent_maps_are_refused() {
    let mut m = map();
    m.n_obstacles = MAX_OBSTACLES as u32 + 1;
    assert!(matches!(
        Sensing::new(&m, 0),
        Err(SensingError::InvalidMap(_))
    ));

    let mut m = map();
    m.sensors.lidar_range_std = -0.1;
    assert_eq!(
        Sensing::new(&m, 0).err(),
        Some(SensingError::OutOfRange {
            field: "sensors.lidar_range_std",
            value: -0.1
        })
    );

    let mut m = map();
    m.sensors.lidar_fov = 0.0;
    assert!(matches!(
        Sensing::new(&m, 0),
        Err(SensingError::OutOfRange {
            field: "sensors.lidar_fov",
            ..
        })
    ));
    m.sensors.lidar_beams = 0;
    assert!(Sensing::new(&m, 0).is_ok());

    let mut m = map();
    m.arena_width = f64::NAN;
    assert!(Sensing::new(&m, 0).is_err());
}

#[test]
fn garbage_truth_never_panics() {
    let m = noisy_map();
    let mut s = sensing(&m);
    let mut t = truth(f64::NAN, f64::INFINITY, f64::NAN);
    t.contacts[0] = Contact {
        px: f64::NAN,
        py: 1.0,
        nx: f64::INFINITY,
        ny: 0.0,
        depth: 1e300,
    };
    t.n_contacts = 99;
    t.header.tick = u64::MAX;
    let mut scan: Box<Scan> = bytemuck::zeroed_box();
    let mut tac: Box<Tactile> = bytemuck::zeroed_box();
    let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
    let mut odom: Odom = bytemuck::Zeroable::zeroed();
    let mut fix: Fix = bytemuck::Zeroable::zeroed();
    s.scan(&t, &mut scan);
    s.tactile(&t, &mut tac);
    s.odom(&t, &mut odom);
    s.beacons(&t, &mut beacons);
    s.fix(&t, &mut fix);
    assert_eq!(scan.validate(), Ok(()));
    assert_eq!(beacons.n_readings, 0);
}
