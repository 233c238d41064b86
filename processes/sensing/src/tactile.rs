//! Tactile geometry: where the k rim sensors sit and how a contact is shared between them
//! (the k force vectors of algorithms §2.2's f_net).

use core::f64::consts::TAU;

/// Shares below this go to the other sensor (a direction within ~1e-9 of a sensor's angle).
pub const SNAP_SHARE: f64 = 1e-9;

/// Angle of sensor `i` of `k` in the robot frame: 2πi/k, in `[0, 2π)`.
#[inline]
pub fn sensor_angle(i: usize, k: usize) -> f64 {
    if k == 0 {
        0.0
    } else {
        TAU * i as f64 / k as f64
    }
}

/// Shares a contact seen at robot-frame direction `phi` (rad) between the two nearest of `k`
/// sensors, linearly by angular distance: returns `[(i0, w0), (i1, w1)]` with `w0 + w1 = 1`,
/// `w0` the weight of the sensor at or just before `phi` (counter-clockwise order).
///
/// A contact right on sensor `i` gives `[(i, 1), (i + 1, 0)]`; halfway between two sensors
/// gives ½ each; with `k = 1` both entries name sensor 0. `k = 0` or a non-finite `phi` gives
/// zero weights.
pub fn split_between_sensors(phi: f64, k: usize) -> [(usize, f64); 2] {
    if k == 0 || !phi.is_finite() {
        return [(0, 0.0), (0, 0.0)];
    }
    let u = phi.rem_euclid(TAU) / (TAU / k as f64);
    let base = u.floor();
    let frac = (u - base).clamp(0.0, 1.0);
    // `u` can round up to exactly k; the modulo folds it back onto sensor 0.
    let i0 = (base as usize) % k;
    let i1 = (i0 + 1) % k;
    // A contact on a sensor, up to rounding, must not leak a vanishing share (and with it the
    // sensor noise) onto its neighbour: snap shares below SNAP_SHARE.
    if frac < SNAP_SHARE {
        [(i0, 1.0), (i1, 0.0)]
    } else if frac > 1.0 - SNAP_SHARE {
        [(i0, 0.0), (i1, 1.0)]
    } else {
        [(i0, 1.0 - frac), (i1, frac)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use core::f64::consts::PI;
    use proptest::prelude::*;

    #[test]
    fn straight_ahead_lands_on_sensor_zero() {
        assert_eq!(split_between_sensors(0.0, 8), [(0, 1.0), (1, 0.0)]);
        // Just below 0 (clockwise of the heading) sensor 7 gets a small share; within rounding of
        // sensor 0, nothing leaks to its neighbours.
        let [(i0, w0), (i1, w1)] = split_between_sensors(-1e-6, 8);
        assert_eq!((i0, i1), (7, 0));
        assert!(w1 > 0.999 && w0 > 0.0);
        assert_eq!(split_between_sensors(-1e-15, 8), [(7, 0.0), (0, 1.0)]);
        assert_eq!(split_between_sensors(1e-15, 8), [(0, 1.0), (1, 0.0)]);
    }

    #[test]
    fn halfway_splits_evenly_and_wraps() {
        let [(i0, w0), (i1, w1)] = split_between_sensors(PI / 8.0, 8);
        assert_eq!((i0, i1), (0, 1));
        assert_relative_eq!(w0, 0.5, epsilon = 1e-12);
        assert_relative_eq!(w1, 0.5, epsilon = 1e-12);
        // Between sensor 7 (at 7π/4) and sensor 0, a quarter of the way.
        let [(i0, w0), (i1, w1)] = split_between_sensors(7.0 * PI / 4.0 + PI / 16.0, 8);
        assert_eq!((i0, i1), (7, 0));
        assert_relative_eq!(w0, 0.75, epsilon = 1e-9);
        assert_relative_eq!(w1, 0.25, epsilon = 1e-9);
        // One sensor takes everything.
        let [(a, wa), (b, wb)] = split_between_sensors(2.0, 1);
        assert_eq!((a, b), (0, 0));
        assert_relative_eq!(wa + wb, 1.0);
        assert_eq!(split_between_sensors(1.0, 0), [(0, 0.0), (0, 0.0)]);
        assert_eq!(split_between_sensors(f64::NAN, 4), [(0, 0.0), (0, 0.0)]);
    }

    proptest! {
        #[test]
        fn weights_sum_to_one_and_pick_adjacent_sensors(phi in -20.0f64..20.0, k in 1usize..33) {
            let [(i0, w0), (i1, w1)] = split_between_sensors(phi, k);
            prop_assert!(i0 < k && i1 < k);
            prop_assert_eq!(i1, (i0 + 1) % k);
            prop_assert!((0.0..=1.0).contains(&w0) && (0.0..=1.0).contains(&w1));
            prop_assert!((w0 + w1 - 1.0).abs() < 1e-12);
            // The heavier sensor is the angularly nearer one.
            let near = if w0 >= w1 { i0 } else { i1 };
            let d = |i: usize| mole_types::wrap_angle(phi - sensor_angle(i, k)).abs();
            prop_assert!(d(near) <= d(i0).min(d(i1)) + 1e-9);
        }
    }
}
