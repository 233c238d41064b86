//! Wheel odometry while the robot pushes against a wall (algorithms §6.6, "Against a wall").
//!
//! The wheels report the velocities they turn at; when a wall blocks the robot, the body moves
//! less, and slides along the wall. The tactile ring of the same step says where the walls are:
//! each contact pushes the robot along its normal, so the part of the wheels' chord that runs into
//! a contact is taken out, and what is left is the motion, an arc along the wheels' chord plus a
//! sideways slide the unicycle cannot make. Without this an estimator believes every blocked
//! step's phantom motion: on a dark room bumped by a random walk its pose NEES was 1–5 between
//! contacts and 50–370 across them.

use crate::models::sinc;
use mole_types::{MAX_TACTILE, Odom, Tactile};
use nalgebra::{Rotation2, Vector2};

/// A contact whose summed force is below this many σ of the sensors' noise gives its direction
/// by where it sits on the rim instead (a force that small says nothing of the normal).
const FORCE_SIGMAS: f64 = 3.0;

/// Times the chord is projected against every normal: two walls meeting at a corner need the
/// second pass (sliding along one runs into the other).
const PASSES: usize = 2;

/// A step's motion against contacts: the wheels' odometry with v along the chord left, and
/// the slide sideways of it, in the robot frame of the pose the step ends in (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Slide {
    pub odom: Odom,
    pub sideways: Vector2<f64>,
}

/// The unit normals (robot frame, pointing from the wall into the robot) of the contacts on the
/// tactile ring: one per run of neighbouring loaded sensors (an unloaded sensor reads exactly
/// zero), its direction that of the run's summed force, or, when that force is below
/// [`FORCE_SIGMAS`]·σ·√(sensors), away from the run's place on the rim. Writes them into `out`
/// and returns how many.
pub fn contact_normals(
    tactile: &Tactile,
    force_std: f64,
    out: &mut [Vector2<f64>; MAX_TACTILE],
) -> usize {
    let sensors = tactile.sensors();
    let k = sensors.len();
    if k == 0 {
        return 0;
    }
    let loaded = |i: usize| {
        let s = &sensors[i % k];
        (s.fx != 0.0 || s.fy != 0.0) && s.fx.is_finite() && s.fy.is_finite()
    };
    // Start after an unloaded sensor so that no run wraps past the start (none: all loaded).
    let start = (0..k).find(|&i| !loaded(i)).map_or(0, |i| i + 1);
    let (mut n, mut i) = (0, 0);
    while i < k {
        if !loaded(start + i) {
            i += 1;
            continue;
        }
        let (mut force, mut rim, mut m) = (Vector2::zeros(), Vector2::zeros(), 0);
        while i < k && loaded(start + i) {
            let s = &sensors[(start + i) % k];
            force += Vector2::new(f64::from(s.fx), f64::from(s.fy));
            let a = f64::from(s.angle);
            rim += Vector2::new(a.cos(), a.sin());
            (i, m) = (i + 1, m + 1);
        }
        let weak = force.norm() < FORCE_SIGMAS * force_std.max(0.0) * (m as f64).sqrt();
        let normal = if weak { -rim } else { force };
        if let Some(unit) = normal.try_normalize(1e-12) {
            out[n] = unit;
            n += 1;
        }
    }
    n
}

/// The motion of a step whose wheels turned against the contacts of `tactile` (read at the
/// step's end), or None when no contact blocked the chord. In the frame of the start pose the
/// wheels' chord c = s·(cos h, sin h), h = ω·dt/2 (algorithms §6.6) loses its component into
/// each normal n where c·n < 0 ([`PASSES`] times over); what is left, p, is written as the arc
/// with s' = p·(cos h, sin h) and the slide l = p·(−sin h, cos h) across it. The turn is the
/// wheels': a wall stops translation, not rotation.
pub fn slide_along_contacts(odom: &Odom, tactile: &Tactile, force_std: f64) -> Option<Slide> {
    let mut normals = [Vector2::zeros(); MAX_TACTILE];
    let n = contact_normals(tactile, force_std, &mut normals);
    if n == 0 || !(odom.dt > 0.0 && odom.v.is_finite() && odom.omega.is_finite()) {
        return None;
    }
    let half = 0.5 * odom.omega * odom.dt;
    let length = odom.v * odom.dt * sinc(half);
    let along = Vector2::new(half.cos(), half.sin());
    let chord = along * length;
    // The tactile ring is read at the end pose, turned by 2h from the start.
    let to_start = Rotation2::new(2.0 * half);
    let mut p = chord;
    for _ in 0..PASSES {
        for normal in &normals[..n] {
            let normal = to_start * normal;
            let into = p.dot(&normal);
            if into < 0.0 {
                p -= normal * into;
            }
        }
    }
    if (p - chord).norm() <= 1e-12 * (1.0 + chord.norm()) {
        return None;
    }
    let across = Vector2::new(-half.sin(), half.cos());
    let mut arc = *odom;
    arc.v = p.dot(&along) / (odom.dt * sinc(half));
    // l·(−sin h, cos h) in the start frame is l·(sin h, cos h) in the end frame.
    let sideways = Vector2::new(half.sin(), half.cos()) * p.dot(&across);
    Some(Slide {
        odom: arc,
        sideways,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use core::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};
    use mole_types::TactileReading;

    const K: usize = 32;

    /// A ring of K sensors with a wall at robot-frame direction `at` (rad) pressing `force` N on
    /// the two sensors either side of it, along its normal.
    fn ring(walls: &[(f64, f64)]) -> Tactile {
        let mut t: Tactile = bytemuck::Zeroable::zeroed();
        t.n_sensors = K as u32;
        for (i, s) in t.sensors.iter_mut().enumerate().take(K) {
            s.angle = (2.0 * PI * i as f64 / K as f64) as f32;
        }
        for &(at, force) in walls {
            let u = at.rem_euclid(2.0 * PI) / (2.0 * PI / K as f64);
            let i0 = u.floor() as usize % K;
            for i in [i0, (i0 + 1) % K] {
                let s: &mut TactileReading = &mut t.sensors[i];
                s.fx += (-force * at.cos() / 2.0) as f32;
                s.fy += (-force * at.sin() / 2.0) as f32;
            }
        }
        t
    }

    fn odom(v: f64, omega: f64) -> Odom {
        Odom {
            v,
            omega,
            dt: 0.01,
            ..bytemuck::Zeroable::zeroed()
        }
    }

    /// The slid motion as a displacement in the start frame: the arc's chord plus the slide.
    fn displacement(slide: &Slide) -> Vector2<f64> {
        let o = &slide.odom;
        let half = 0.5 * o.omega * o.dt;
        let chord = Vector2::new(half.cos(), half.sin()) * o.v * o.dt * sinc(half);
        chord + Rotation2::new(2.0 * half) * slide.sideways
    }

    #[test]
    fn a_wall_straight_ahead_stops_the_robot_and_one_behind_does_not() {
        let s = slide_along_contacts(&odom(0.8, 0.0), &ring(&[(0.0, 4.0)]), 0.05).unwrap();
        assert_relative_eq!(s.odom.v, 0.0, epsilon = 1e-9);
        assert_relative_eq!(s.sideways.norm(), 0.0, epsilon = 1e-9);
        // Driving away from it, or turning on the spot, nothing is blocked.
        assert!(slide_along_contacts(&odom(-0.8, 0.0), &ring(&[(0.0, 4.0)]), 0.05).is_none());
        assert!(slide_along_contacts(&odom(0.0, 1.0), &ring(&[(0.0, 4.0)]), 0.05).is_none());
        assert!(slide_along_contacts(&odom(0.8, 0.0), &ring(&[]), 0.05).is_none());
    }

    /// At 45° to a wall the robot keeps the half of its chord that runs along it, a quarter of
    /// the wheels' displacement ahead and a quarter across (the world's contact resolution does
    /// the same, processes/world/src/world.rs).
    #[test]
    fn at_an_angle_the_robot_slides_along_the_wall() {
        let s = slide_along_contacts(&odom(1.0, 0.0), &ring(&[(FRAC_PI_4, 2.0)]), 0.05).unwrap();
        let d = displacement(&s);
        let n = Vector2::new(-FRAC_PI_4.cos(), -FRAC_PI_4.sin());
        assert!(d.dot(&n).abs() < 1e-6, "nothing into the wall: {d}");
        assert_relative_eq!(d, Vector2::new(0.005, -0.005), epsilon = 2e-4);
        assert_relative_eq!(s.odom.v * 0.01, d.x, epsilon = 1e-12);
        // Turning as it slides: the arc and the slide still add up to a chord along the wall.
        let turning = odom(1.0, 2.0);
        let s = slide_along_contacts(&turning, &ring(&[(FRAC_PI_4, 2.0)]), 0.05).unwrap();
        let n_start = Rotation2::new(0.02) * n;
        assert!(displacement(&s).dot(&n_start).abs() < 1e-6);
        assert_eq!(s.odom.omega, turning.omega);
    }

    #[test]
    fn in_a_corner_nothing_is_left() {
        let corner = ring(&[(FRAC_PI_4, 2.0), (-FRAC_PI_4, 2.0)]);
        let s = slide_along_contacts(&odom(1.0, 0.0), &corner, 0.05).unwrap();
        assert!(displacement(&s).norm() < 1e-9, "{}", displacement(&s));
        let s = slide_along_contacts(&odom(1.0, 0.0), &ring(&[(FRAC_PI_2, 2.0)]), 0.05);
        assert!(
            s.is_none(),
            "a wall to the side does not block driving ahead"
        );
    }

    /// A force within the sensors' noise gives the direction of where it touches instead: a
    /// noise-sized force pointing sideways on a contact straight ahead still stops the robot.
    #[test]
    fn a_faint_contact_is_taken_by_where_it_touches() {
        let mut t = ring(&[]);
        t.sensors[0].fx = 0.0;
        t.sensors[0].fy = 0.01;
        let mut normals = [Vector2::zeros(); MAX_TACTILE];
        assert_eq!(contact_normals(&t, 0.05, &mut normals), 1);
        assert_relative_eq!(normals[0], Vector2::new(-1.0, 0.0), epsilon = 1e-6);
        assert_eq!(contact_normals(&t, 0.001, &mut normals), 1);
        assert_relative_eq!(normals[0], Vector2::new(0.0, 1.0), epsilon = 1e-6);
        // A run over the start of the ring (sensors 31 and 0) is one contact.
        let t = ring(&[(-0.05, 2.0)]);
        assert_eq!(contact_normals(&t, 0.05, &mut normals), 1);
        let t = ring(&[(FRAC_PI_4, 2.0), (PI, 2.0)]);
        assert_eq!(contact_normals(&t, 0.05, &mut normals), 2);
    }
}
