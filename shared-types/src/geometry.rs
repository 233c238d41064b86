//! Plain geometry shared by the process libraries and embedded in messages.
//!
//! The world frame: x to the right, y up, metres; the arena spans `[0, width] × [0, height]`.
//! Headings are radians, counter-clockwise from +x, wrapped to `(-π, π]`.

use crate::Layout;
use bytemuck::{Pod, Zeroable};
use iceoryx2_bb_derive_macros::ZeroCopySend;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;

/// A planar pose: position (m) and heading θ (rad).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose2 {
    pub x: f64,
    pub y: f64,
    pub theta: f64,
}

impl Pose2 {
    pub const fn new(x: f64, y: f64, theta: f64) -> Self {
        Self { x, y, theta }
    }
}

/// An axis-aligned square obstacle of side `side` centred at `(cx, cy)` (algorithms §1.3).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, Pod, Zeroable, ZeroCopySend, Layout)]
#[type_name("mole.Square.v1")]
#[layout(size = 24)]
pub struct Square {
    pub cx: f64,
    pub cy: f64,
    pub side: f64,
}

impl Square {
    pub const fn new(cx: f64, cy: f64, side: f64) -> Self {
        Self { cx, cy, side }
    }
    /// Lower-left corner.
    pub fn min(&self) -> (f64, f64) {
        (self.cx - self.side / 2.0, self.cy - self.side / 2.0)
    }
    /// Upper-right corner.
    pub fn max(&self) -> (f64, f64) {
        (self.cx + self.side / 2.0, self.cy + self.side / 2.0)
    }
    /// Whether the point lies inside or on the square.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        let h = self.side / 2.0;
        (x - self.cx).abs() <= h && (y - self.cy).abs() <= h
    }
}

/// A beacon at a known position, seen by range and bearing.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, Pod, Zeroable, ZeroCopySend, Layout)]
#[type_name("mole.BeaconSite.v1")]
#[layout(size = 24)]
pub struct BeaconSite {
    pub x: f64,
    pub y: f64,
    pub id: u32,
    pub _pad: u32,
}

/// One contact between the robot's rim and the world, in the world frame.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, Pod, Zeroable, ZeroCopySend, Layout)]
#[type_name("mole.Contact.v1")]
#[layout(size = 40)]
pub struct Contact {
    /// Contact point on the robot's rim (m).
    pub px: f64,
    pub py: f64,
    /// Unit normal pointing from the obstacle into the robot.
    pub nx: f64,
    pub ny: f64,
    /// How far the motion of this step pushed the rim into the obstacle before it was resolved (m).
    pub depth: f64,
}

/// Wraps an angle to `(-π, π]`.
#[inline]
pub fn wrap_angle(a: f64) -> f64 {
    use core::f64::consts::{PI, TAU};
    let mut r = a.rem_euclid(TAU);
    if r > PI {
        r -= TAU;
    }
    r
}

/// Exact unicycle motion over `h` at constant `(v, ω)` (algorithms §6.3's motion model): an
/// arc of radius v/ω, or a straight line when ω·h is negligible (then the chord along the mid
/// heading, exact to O((ωh)²)).
pub fn unicycle_arc(p: Pose2, v: f64, omega: f64, h: f64) -> Pose2 {
    let turn = omega * h;
    let (x, y) = if turn.abs() < 1e-9 {
        let mid = p.theta + 0.5 * turn;
        (p.x + v * h * mid.cos(), p.y + v * h * mid.sin())
    } else {
        let radius = v / omega;
        let th1 = p.theta + turn;
        (
            p.x + radius * (th1.sin() - p.theta.sin()),
            p.y - radius * (th1.cos() - p.theta.cos()),
        )
    };
    Pose2::new(x, y, wrap_angle(p.theta + turn))
}

/// The one unicycle arc `(s, dθ)` that takes `from` to `to`: the inverse of [`unicycle_arc`]
/// over h = 1 (s = v·h, dθ = ω·h), for a turn of less than π (a longer one is taken the short way round).
pub fn arc_between(from: Pose2, to: Pose2) -> (f64, f64) {
    let (c, n) = (from.theta.cos(), from.theta.sin());
    let (ex, ey) = (to.x - from.x, to.y - from.y);
    // The chord in `from`'s frame; an arc's chord points half its turn off the heading.
    let (dx, dy) = (c * ex + n * ey, -n * ex + c * ey);
    let dtheta = wrap_angle(to.theta - from.theta);
    let half = dtheta / 2.0;
    let chord = dx.hypot(dy);
    let length = if half.abs() < 1e-9 {
        chord
    } else {
        chord * half / half.sin()
    };
    let forward = dx * half.cos() + dy * half.sin() >= 0.0;
    (if forward { length } else { -length }, dtheta)
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f64::consts::PI;

    /// An arc and back: straight, turning either way, backwards, and across the ±π seam.
    #[test]
    fn arc_between_inverts_unicycle_arc() {
        let starts = [
            Pose2::new(1.0, 2.0, 0.3),
            Pose2::new(-4.0, 0.5, 3.1),
            Pose2::new(0.0, 0.0, -2.9),
        ];
        for from in starts {
            for (s, dtheta) in [(0.5, 0.0), (0.3, 0.4), (0.3, -1.2), (-0.2, 0.7), (0.0, 0.5)] {
                let to = unicycle_arc(from, s, dtheta, 1.0);
                let (s2, dtheta2) = arc_between(from, to);
                assert!((s2 - s).abs() < 1e-9, "{from:?} {s} {dtheta}: s {s2}");
                assert!(
                    (dtheta2 - dtheta).abs() < 1e-9,
                    "{from:?} {s} {dtheta}: dθ {dtheta2}"
                );
            }
        }
        // Straight ahead along the heading, a quarter circle of radius 1.
        let p = unicycle_arc(Pose2::new(0.0, 0.0, 0.0), PI / 2.0, PI / 2.0, 1.0);
        assert!(
            (p.x - 1.0).abs() < 1e-12 && (p.y - 1.0).abs() < 1e-12,
            "{p:?}"
        );
    }

    #[test]
    fn wrap_angle_stays_in_half_open_interval() {
        for k in -20..=20 {
            let a = k as f64 * 0.7;
            let w = wrap_angle(a);
            assert!(w > -PI && w <= PI, "{a} -> {w}");
            assert!(
                ((a - w) / (2.0 * PI)).fract().abs() < 1e-9
                    || ((a - w) / (2.0 * PI)).fract().abs() > 1.0 - 1e-9
            );
        }
        assert_eq!(wrap_angle(PI), PI);
        assert_eq!(wrap_angle(-PI), PI);
    }

    #[test]
    fn square_corners_and_containment() {
        let s = Square::new(2.0, 3.0, 1.0);
        assert_eq!(s.min(), (1.5, 2.5));
        assert_eq!(s.max(), (2.5, 3.5));
        assert!(s.contains(2.5, 3.5));
        assert!(!s.contains(2.6, 3.0));
    }
}
