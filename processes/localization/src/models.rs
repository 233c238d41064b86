//! The motion and measurement models every estimator shares: the unicycle g(x, u) with its
//! Jacobians, the range-bearing h(x) to a known beacon with its Jacobian, and the beacon table.
//!
//! Algorithms §6.6 writes x_t = g(x_{t-1}, u_t) + ε_t and z_t = h(x_t) + δ_t; the forms below are the
//! velocity motion model and the range-bearing landmark model of Thrun et al., *Probabilistic
//! Robotics*, §5.3 and §6.6.

use mole_types::{BeaconSite, MAX_BEACONS, wrap_angle};
use nalgebra::{Matrix2x3, Matrix3, Matrix3x2, Vector2, Vector3};

/// Below this |a| the sinc terms use their Taylor series (error < 1e-20, no cancellation).
pub(crate) const SINC_SERIES_BELOW: f64 = 1e-3;

/// Wraps an angle to (−π, π] with at most two ±2π steps (no fmod, no libm call), falling back
/// to [`wrap_angle`] when |a| ≥ 5π; for the per-particle and per-cell hot loops.
#[inline]
pub(crate) fn wrap_near(a: f64) -> f64 {
    use core::f64::consts::{PI, TAU};
    let mut r = a;
    if r > PI {
        r -= TAU;
        if r > PI {
            r -= TAU;
        }
    } else if r <= -PI {
        r += TAU;
        if r <= -PI {
            r += TAU;
        }
    }
    if r > -PI && r <= PI { r } else { wrap_angle(a) }
}

/// sin(a)/a, with the limit 1 at a = 0.
#[inline]
pub(crate) fn sinc(a: f64) -> f64 {
    if a.abs() < SINC_SERIES_BELOW {
        let a2 = a * a;
        1.0 - a2 / 6.0 + a2 * a2 / 120.0
    } else {
        a.sin() / a
    }
}

/// d/da of sin(a)/a, with the limit 0 at a = 0.
#[inline]
fn sinc_prime(a: f64) -> f64 {
    if a.abs() < SINC_SERIES_BELOW {
        -a / 3.0 + a * a * a / 30.0
    } else {
        (a * a.cos() - a.sin()) / (a * a)
    }
}

/// The chord of one step: length s = v·dt·sinc(ω·dt/2) along the heading φ = θ + ω·dt/2.
///
/// The exact arc (Thrun §5.3) x' = x + v/ω·(sin(θ+ωdt) − sin θ) equals
/// x + s·cos φ by the sum-to-product identities; this form has no 1/ω and so no special case
/// for straight driving.
#[inline]
fn chord(theta: f64, v: f64, omega: f64, dt: f64) -> (f64, f64, f64) {
    let half = 0.5 * omega * dt;
    (v * dt * sinc(half), theta + half, half)
}

/// g(μ, u): the unicycle moved by (v, ω) for dt along the exact arc (algorithms §6.6, Thrun §5.3);
/// the straight-line limit as ω → 0 is built in. θ comes back wrapped to (−π, π].
pub fn unicycle_g(mu: &Vector3<f64>, v: f64, omega: f64, dt: f64) -> Vector3<f64> {
    let (s, phi, _) = chord(mu[2], v, omega, dt);
    Vector3::new(
        mu[0] + s * phi.cos(),
        mu[1] + s * phi.sin(),
        wrap_angle(mu[2] + omega * dt),
    )
}

/// Adds to a moved pose `mu` (θ its heading after the move) the slide `sideways` its wheels did
/// not see (robot frame, m; [`crate::contact`]) and to the motion Jacobian `g_t` the slide's
/// turn with θ, ∂(R(θ)·b)/∂θ = (−(R(θ)b)_y, (R(θ)b)_x) (algorithms §6.6, "Against a wall").
pub fn add_slide(mu: &mut Vector3<f64>, g_t: Option<&mut Matrix3<f64>>, sideways: &Vector2<f64>) {
    let (sin_t, cos_t) = mu[2].sin_cos();
    let (dx, dy) = (
        cos_t * sideways[0] - sin_t * sideways[1],
        sin_t * sideways[0] + cos_t * sideways[1],
    );
    mu[0] += dx;
    mu[1] += dy;
    if let Some(g_t) = g_t {
        g_t[(0, 2)] -= dy;
        g_t[(1, 2)] += dx;
    }
}

/// G_t = ∂g/∂x at (μ, u), analytic (algorithms §6.6).
pub fn unicycle_jacobian_g(mu: &Vector3<f64>, v: f64, omega: f64, dt: f64) -> Matrix3<f64> {
    let (s, phi, _) = chord(mu[2], v, omega, dt);
    Matrix3::new(
        1.0,
        0.0,
        -s * phi.sin(), //
        0.0,
        1.0,
        s * phi.cos(), //
        0.0,
        0.0,
        1.0,
    )
}

/// V_t = ∂g/∂u at (μ, u), u = (v, ω), analytic; maps the odometry noise M_t into the state
/// (R_t = V_t M_t V_tᵀ, Thrun §7.4, Table 7.2).
pub fn unicycle_jacobian_v(mu: &Vector3<f64>, v: f64, omega: f64, dt: f64) -> Matrix3x2<f64> {
    let (_, phi, half) = chord(mu[2], v, omega, dt);
    let (sin_phi, cos_phi) = phi.sin_cos();
    let sc = sinc(half);
    let dsc = sinc_prime(half);
    // ∂s/∂v = dt·sinc, ∂s/∂ω = v·dt·sinc'·dt/2, ∂φ/∂ω = dt/2.
    let ds_dv = dt * sc;
    let ds_domega = v * dt * dsc * 0.5 * dt;
    let s = v * dt * sc;
    let dphi_domega = 0.5 * dt;
    Matrix3x2::new(
        ds_dv * cos_phi,
        ds_domega * cos_phi - s * sin_phi * dphi_domega,
        ds_dv * sin_phi,
        ds_domega * sin_phi + s * cos_phi * dphi_domega,
        0.0,
        dt,
    )
}

/// h(x) = (range, bearing) from pose x to the beacon at (bx, by); the bearing is relative to
/// the heading and wrapped (Thrun §6.6).
pub fn range_bearing_h(x: &Vector3<f64>, beacon: (f64, f64)) -> Vector2<f64> {
    let dx = beacon.0 - x[0];
    let dy = beacon.1 - x[1];
    Vector2::new(dx.hypot(dy), wrap_angle(dy.atan2(dx) - x[2]))
}

/// H_t = ∂h/∂x at x, analytic (algorithms §6.6; Thrun §7.4). Undefined at range 0: the
/// rows are then returned as zeros and callers must skip the reading (see [`MIN_RANGE`]).
pub fn range_bearing_jacobian_h(x: &Vector3<f64>, beacon: (f64, f64)) -> Matrix2x3<f64> {
    let dx = beacon.0 - x[0];
    let dy = beacon.1 - x[1];
    let q = dx * dx + dy * dy;
    if q < MIN_RANGE * MIN_RANGE {
        return Matrix2x3::zeros();
    }
    range_bearing_jacobian_at(dx, dy, q, q.sqrt())
}

/// [`range_bearing_jacobian_h`] from the beacon's offset (dx, dy) from the pose, q = dx² + dy²
/// and r = √q, for callers that have them already.
pub fn range_bearing_jacobian_at(dx: f64, dy: f64, q: f64, r: f64) -> Matrix2x3<f64> {
    Matrix2x3::new(
        -dx / r,
        -dy / r,
        0.0, //
        dy / q,
        -dx / q,
        -1.0,
    )
}

/// Below this predicted range (m) the bearing is undefined and a beacon reading is skipped.
pub const MIN_RANGE: f64 = 1e-6;

/// Odometry beyond these bounds is not motion but a broken sensor or a corrupted message: every
/// estimator ignores it (and counts it, [`crate::ReadingError::Invalid`]). The scenarios' robots
/// reach 0.5–2 m/s and 2–4 rad/s and the world steps every 0.01 s, so the bounds leave a wide
/// margin for odometry noise and faster robots while keeping every product v·dt, ω·dt and
/// (v·dt)² of the motion models far from overflow.
///
/// |v| above this (m/s) is ignored.
pub const MAX_ODOM_SPEED: f64 = 50.0;
/// |ω| above this (rad/s) is ignored.
pub const MAX_ODOM_TURN_RATE: f64 = 50.0;
/// dt above this (s) is ignored: one odometry message covers one world step, and a step of a
/// second already means the clock stalled.
pub const MAX_ODOM_DT: f64 = 1.0;

/// Whether odometry (v, ω) over dt describes a motion a robot can make: finite, |v| ≤
/// [`MAX_ODOM_SPEED`], |ω| ≤ [`MAX_ODOM_TURN_RATE`] and 0 ≤ dt ≤ [`MAX_ODOM_DT`].
#[inline]
pub fn odometry_is_plausible(v: f64, omega: f64, dt: f64) -> bool {
    v.abs() <= MAX_ODOM_SPEED
        && omega.abs() <= MAX_ODOM_TURN_RATE
        && (0.0..=MAX_ODOM_DT).contains(&dt)
}

/// [`odometry_is_plausible`] for a step against a wall: the arc's, and a finite slide.
#[inline]
pub fn sliding_is_plausible(v: f64, omega: f64, dt: f64, sideways: &Vector2<f64>) -> bool {
    odometry_is_plausible(v, omega, dt) && sideways.iter().all(|d| d.is_finite())
}

/// Known beacon positions looked up by the id a reading carries, without allocation.
///
/// A reading's id is `BeaconSite::id`. If the map's ids are not unique (e.g. left at zero by a
/// world that numbers beacons by position), the position in `WorldMap::beacons` is the id
/// instead, which is what the message doc ("the beacon's id in `WorldMap::beacons`") also allows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeaconTable {
    sites: [Option<(f64, f64)>; MAX_BEACONS],
}

impl BeaconTable {
    /// Builds the table; sites with non-finite coordinates or ids ≥ `MAX_BEACONS` are left out.
    pub fn new(beacons: &[BeaconSite]) -> Self {
        let beacons = &beacons[..beacons.len().min(MAX_BEACONS)];
        let mut seen = [false; MAX_BEACONS];
        let unique = beacons.iter().all(|b| {
            let i = b.id as usize;
            if i >= MAX_BEACONS || seen[i] {
                return false;
            }
            seen[i] = true;
            true
        });
        let mut sites = [None; MAX_BEACONS];
        for (index, b) in beacons.iter().enumerate() {
            let id = if unique { b.id as usize } else { index };
            if b.x.is_finite() && b.y.is_finite() {
                sites[id] = Some((b.x, b.y));
            }
        }
        Self { sites }
    }

    /// The position of beacon `id`, if the map has it.
    #[inline]
    pub fn get(&self, id: u32) -> Option<(f64, f64)> {
        self.sites.get(id as usize).copied().flatten()
    }

    /// How many beacons the table knows.
    pub fn len(&self) -> usize {
        self.sites.iter().filter(|s| s.is_some()).count()
    }

    /// Whether the table knows no beacon.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use core::f64::consts::{FRAC_PI_2, PI, TAU};
    use proptest::prelude::*;

    /// Central finite difference of f along state coordinate j (θ differences wrapped).
    fn central_diff<const M: usize>(
        f: impl Fn(&Vector3<f64>) -> nalgebra::SVector<f64, M>,
        x: &Vector3<f64>,
        j: usize,
        angle_rows: &[usize],
    ) -> nalgebra::SVector<f64, M> {
        let h = 1e-6;
        let mut xp = *x;
        let mut xm = *x;
        xp[j] += h;
        xm[j] -= h;
        let mut d = f(&xp) - f(&xm);
        for &r in angle_rows {
            d[r] = wrap_angle(d[r]);
        }
        d / (2.0 * h)
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-6 * (1.0 + a.abs().max(b.abs()))
    }

    proptest! {
        #[test]
        fn jacobian_g_matches_central_differences(
            x in -10.0..10.0f64, y in -10.0..10.0f64, th in -PI..PI,
            v in -2.0..2.0f64, omega in prop_oneof![-3.0..3.0f64, -1e-4..1e-4f64, Just(0.0)],
            dt in 0.0..0.5f64,
        ) {
            let mu = Vector3::new(x, y, th);
            let g_t = unicycle_jacobian_g(&mu, v, omega, dt);
            for j in 0..3 {
                let fd = central_diff(|m| unicycle_g(m, v, omega, dt), &mu, j, &[2]);
                for i in 0..3 {
                    prop_assert!(close(g_t[(i, j)], fd[i]), "G[{i},{j}] {} vs {}", g_t[(i, j)], fd[i]);
                }
            }
        }

        #[test]
        fn jacobian_v_matches_central_differences(
            th in -PI..PI, v in -2.0..2.0f64,
            omega in prop_oneof![-3.0..3.0f64, -1e-3..1e-3f64, Just(0.0)],
            dt in 0.0..0.5f64,
        ) {
            let mu = Vector3::new(1.0, -2.0, th);
            let v_t = unicycle_jacobian_v(&mu, v, omega, dt);
            let h = 1e-6;
            let wrap3 = |mut d: Vector3<f64>| { d[2] = wrap_angle(d[2]); d };
            let fd_v = wrap3(unicycle_g(&mu, v + h, omega, dt) - unicycle_g(&mu, v - h, omega, dt)) / (2.0 * h);
            let fd_w = wrap3(unicycle_g(&mu, v, omega + h, dt) - unicycle_g(&mu, v, omega - h, dt)) / (2.0 * h);
            for i in 0..3 {
                prop_assert!(close(v_t[(i, 0)], fd_v[i]), "V[{i},0] {} vs {}", v_t[(i, 0)], fd_v[i]);
                prop_assert!(close(v_t[(i, 1)], fd_w[i]), "V[{i},1] {} vs {}", v_t[(i, 1)], fd_w[i]);
            }
        }

        #[test]
        fn jacobian_h_matches_central_differences(
            x in -10.0..10.0f64, y in -10.0..10.0f64, th in -PI..PI,
            bx in -10.0..10.0f64, by in -10.0..10.0f64,
        ) {
            prop_assume!((bx - x).hypot(by - y) > 0.1);
            let pose = Vector3::new(x, y, th);
            let h_t = range_bearing_jacobian_h(&pose, (bx, by));
            for j in 0..3 {
                let fd = central_diff(|p| range_bearing_h(p, (bx, by)), &pose, j, &[1]);
                for i in 0..2 {
                    prop_assert!(close(h_t[(i, j)], fd[i]), "H[{i},{j}] {} vs {}", h_t[(i, j)], fd[i]);
                }
            }
        }
    }

    #[test]
    fn wrap_near_agrees_with_wrap_angle() {
        for i in -2000..=2000 {
            let a = i as f64 * 0.01 + 0.003;
            assert!((wrap_near(a) - wrap_angle(a)).abs() < 1e-12, "{a}");
        }
        assert_eq!(wrap_near(PI), PI);
        assert_eq!(wrap_near(-PI), PI);
        assert!(wrap_near(f64::NAN).is_nan());
        assert!((wrap_near(1e6) - wrap_angle(1e6)).abs() < 1e-9);
    }

    #[test]
    fn g_is_exact_for_a_straight_line() {
        let mu = Vector3::new(1.0, 2.0, 0.3);
        let out = unicycle_g(&mu, 1.5, 0.0, 2.0);
        assert_relative_eq!(out[0], 1.0 + 3.0 * 0.3f64.cos(), epsilon = 1e-12);
        assert_relative_eq!(out[1], 2.0 + 3.0 * 0.3f64.sin(), epsilon = 1e-12);
        assert_relative_eq!(out[2], 0.3, epsilon = 1e-15);
        // Backwards too.
        let back = unicycle_g(&out, -1.5, 0.0, 2.0);
        assert_relative_eq!(back, mu, epsilon = 1e-12);
    }

    #[test]
    fn g_is_exact_for_a_quarter_and_a_full_circle() {
        // Radius v/ω = 1, centre (0, 1): a quarter turn ends at (1, 1) facing +y.
        let q = unicycle_g(&Vector3::zeros(), 1.0, 1.0, FRAC_PI_2);
        assert_relative_eq!(q, Vector3::new(1.0, 1.0, FRAC_PI_2), epsilon = 1e-12);
        // A full circle of period T returns to the start, in one step or in many.
        let start = Vector3::new(3.0, -1.0, 2.5);
        let (v, omega) = (0.7, 0.35);
        let period = TAU / omega;
        let once = unicycle_g(&start, v, omega, period);
        assert_relative_eq!(once, start, epsilon = 1e-9);
        let mut many = start;
        for _ in 0..1000 {
            many = unicycle_g(&many, v, omega, period / 1000.0);
        }
        assert_relative_eq!(many, start, epsilon = 1e-9);
        // Half way round it is diametrically opposite: 2·v/ω to the left of the start heading.
        let half = unicycle_g(&start, v, omega, period / 2.0);
        let left = Vector2::new(-(2.5f64).sin(), 2.5f64.cos()) * (2.0 * v / omega);
        assert_relative_eq!(half[0], start[0] + left[0], epsilon = 1e-9);
        assert_relative_eq!(half[1], start[1] + left[1], epsilon = 1e-9);
    }

    #[test]
    fn sinc_series_agrees_with_the_closed_form_at_the_switch() {
        for a in [SINC_SERIES_BELOW * 0.999, -SINC_SERIES_BELOW * 0.999] {
            assert!((sinc(a) - a.sin() / a).abs() < 1e-15);
            let direct = (a * a.cos() - a.sin()) / (a * a);
            assert!(
                (sinc_prime(a) - direct).abs() < 1e-11,
                "{} vs {direct}",
                sinc_prime(a)
            );
        }
        assert_eq!(sinc(0.0), 1.0);
        assert_eq!(sinc_prime(0.0), 0.0);
    }

    #[test]
    fn h_gives_range_and_bearing_relative_to_the_heading() {
        let pose = Vector3::new(0.0, 0.0, FRAC_PI_2);
        assert_relative_eq!(range_bearing_h(&pose, (0.0, 2.0)), Vector2::new(2.0, 0.0));
        assert_relative_eq!(
            range_bearing_h(&pose, (1.0, 0.0)),
            Vector2::new(1.0, -FRAC_PI_2),
            epsilon = 1e-15
        );
        // Behind the robot the bearing is π, wrapped into (−π, π].
        assert_relative_eq!(range_bearing_h(&pose, (0.0, -3.0))[1], PI, epsilon = 1e-15);
        assert_eq!(
            range_bearing_jacobian_h(&pose, (0.0, 0.0)),
            Matrix2x3::zeros()
        );
    }

    #[test]
    fn beacon_table_uses_ids_and_falls_back_to_positions() {
        let site = |x, id| BeaconSite {
            x,
            y: 0.0,
            id,
            _pad: 0,
        };
        let t = BeaconTable::new(&[site(1.0, 7), site(2.0, 3), site(f64::NAN, 4)]);
        assert_eq!(t.get(7), Some((1.0, 0.0)));
        assert_eq!(t.get(3), Some((2.0, 0.0)));
        assert_eq!(t.get(4), None);
        assert_eq!(t.get(0), None);
        assert_eq!(t.get(u32::MAX), None);
        assert_eq!(t.len(), 2);
        // Ids all zero: not unique, so the list position is the id.
        let t = BeaconTable::new(&[site(1.0, 0), site(2.0, 0)]);
        assert_eq!(t.get(0), Some((1.0, 0.0)));
        assert_eq!(t.get(1), Some((2.0, 0.0)));
        assert!(BeaconTable::new(&[]).is_empty());
    }
}
