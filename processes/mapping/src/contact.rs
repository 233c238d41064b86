//! The contact grid of algorithms §2.2: M_t, 1 where the robot has touched an obstacle, else 0.

use crate::{GridGeometry, MappingError};
use mole_types::{GRID_CONTACT, Grid, MAX_TACTILE, Pose2, Tactile, wrap_angle};

/// Contact points on the rim, robot frame (m), from one tactile reading (algorithms §2.3).
///
/// Algorithms §2.3 relates f_net = J·p_net with J unspecified; per docs/errata.md we read the
/// forces directly instead: a sensor whose |f| exceeds `force_threshold` is touching, angularly
/// adjacent touching sensors (no quiet sensor between them) share one contact, and that contact
/// lies on the rim opposite their summed force, at direction atan2(−F_y, −F_x), because the
/// obstacle pushes the disk along the contact normal, towards its centre. Two separate runs of
/// touching sensors (a corner, two walls) give two contacts; a run whose forces cancel gives
/// none. Writes up to `MAX_TACTILE` points
/// into `out` and returns how many; a non-finite or non-positive radius gives none, and sensors
/// with a non-finite angle or force are treated as absent or quiet.
pub fn estimate_contacts(
    tactile: &Tactile,
    force_threshold: f64,
    out: &mut [(f64, f64); MAX_TACTILE],
) -> usize {
    let radius = tactile.radius as f64;
    if !(radius.is_finite() && radius > 0.0) {
        return 0;
    }
    let sensors = tactile.sensors();
    // Sensors with a usable angle, in order around the rim (insertion sort: k <= 32, no heap).
    let mut order = [0usize; MAX_TACTILE];
    let mut k = 0;
    for (i, s) in sensors.iter().enumerate() {
        if !s.angle.is_finite() {
            continue;
        }
        let a = wrap_angle(s.angle as f64);
        let mut j = k;
        while j > 0 && wrap_angle(sensors[order[j - 1]].angle as f64) > a {
            order[j] = order[j - 1];
            j -= 1;
        }
        order[j] = i;
        k += 1;
    }
    let force = |pos: usize| {
        let s = &sensors[order[pos % k]];
        (s.fx as f64, s.fy as f64)
    };
    let touching = |pos: usize| {
        let (fx, fy) = force(pos);
        fx.is_finite() && fy.is_finite() && fx.hypot(fy) > force_threshold
    };
    let mut n = 0;
    // A run's forces (Σf_x, Σf_y, Σ|f|) become one contact, unless they (nearly) cancel: then
    // the robot is squeezed from opposite sides and the summed direction means nothing.
    let mut flush = |sum: &mut (f64, f64, f64), n: &mut usize| {
        let (fx, fy, magnitudes) = *sum;
        *sum = (0.0, 0.0, 0.0);
        if fx.hypot(fy) > 1e-3 * magnitudes && *n < MAX_TACTILE {
            let phi = (-fy).atan2(-fx);
            out[*n] = (radius * phi.cos(), radius * phi.sin());
            *n += 1;
        }
    };
    let add = |sum: &mut (f64, f64, f64), pos: usize| {
        let (fx, fy) = force(pos);
        *sum = (sum.0 + fx, sum.1 + fy, sum.2 + fx.hypot(fy));
    };
    let mut sum = (0.0, 0.0, 0.0);
    match (0..k).find(|&pos| !touching(pos)) {
        // Every sensor touches: one contact from the total force (if it does not cancel out).
        None => {
            for pos in 0..k {
                add(&mut sum, pos);
            }
            flush(&mut sum, &mut n);
        }
        // Walk once around the rim starting after a quiet sensor, so no run is split at the seam.
        Some(quiet) => {
            for step in 1..=k {
                let pos = quiet + step;
                if touching(pos) {
                    add(&mut sum, pos);
                } else {
                    flush(&mut sum, &mut n);
                }
            }
        }
    }
    n
}

/// Algorithms §2 contact mapping, with the erratum in docs/errata.md: read J as the rotation from sensor to
/// world frame; contact point = robot position + R(θ)·(sensor offset + estimated contact offset).
#[derive(Debug, Clone)]
pub struct ContactGrid {
    geometry: GridGeometry,
    /// Algorithms §2.2's M_t: 1 occupied, 0 free or unknown; M_0 is all zeros.
    cells: Vec<u8>,
    /// Contact points of the last `integrate_tactile`, world frame.
    points: [(f64, f64); MAX_TACTILE],
    n_points: usize,
}

impl ContactGrid {
    /// An all-zero grid (algorithms §2.2: M_0 is a null matrix) over `[0, width_m] × [0, height_m]`.
    pub fn new(width_m: f64, height_m: f64, resolution: f64) -> Result<ContactGrid, MappingError> {
        let geometry = GridGeometry::for_arena(width_m, height_m, resolution)?;
        Ok(Self {
            cells: vec![0; geometry.len()],
            geometry,
            points: [(0.0, 0.0); MAX_TACTILE],
            n_points: 0,
        })
    }

    /// The grid's size and placement.
    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    /// Algorithms §2.2's cells (0 free or unknown, 1 occupied), row-major.
    pub fn cells(&self) -> &[u8] {
        &self.cells
    }

    /// The world contact points found by the last `integrate_tactile`.
    pub fn contacts(&self) -> &[(f64, f64)] {
        &self.points[..self.n_points]
    }

    /// Forgets every contact.
    pub fn clear(&mut self) {
        self.cells.fill(0);
        self.n_points = 0;
    }

    /// Marks the cell holding world point `(x, y)` occupied; returns whether it lies in the grid.
    pub fn mark_occupied(&mut self, x: f64, y: f64) -> bool {
        match self.geometry.world_to_index(x, y) {
            Some(idx) => {
                self.cells[idx] = 1;
                true
            }
            None => false,
        }
    }

    /// From one tactile reading taken at `pose` (estimated): estimates the contacts on the rim
    /// ([`estimate_contacts`]), transforms each with the pose into the world frame (docs/errata.md,
    /// §2.3: p_world = (x, y) + R(θ)·p_robot), marks its cell 1 and returns the points that
    /// fell inside the grid, so the caller can also mark them in the frontier grid. A non-finite
    /// pose gives no contact.
    pub fn integrate_tactile(
        &mut self,
        pose: Pose2,
        tactile: &Tactile,
        force_threshold: f64,
    ) -> &[(f64, f64)] {
        self.n_points = 0;
        if !(pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite()) {
            return &[];
        }
        let mut robot_frame = [(0.0, 0.0); MAX_TACTILE];
        let n = estimate_contacts(tactile, force_threshold, &mut robot_frame);
        let (s, c) = pose.theta.sin_cos();
        for &(px, py) in &robot_frame[..n] {
            let x = pose.x + c * px - s * py;
            let y = pose.y + s * px + c * py;
            if self.mark_occupied(x, y) {
                self.points[self.n_points] = (x, y);
                self.n_points += 1;
            }
        }
        self.contacts()
    }

    /// Takes over a contact grid published by the mapping process being replaced (a hot
    /// swap); returns false, changing nothing, for a grid of another kind or geometry.
    pub fn restore(&mut self, grid: &Grid) -> bool {
        if grid.kind != GRID_CONTACT || !self.geometry.matches(grid) {
            return false;
        }
        let n = self.geometry.len();
        for (cell, &class) in self.cells.iter_mut().zip(&grid.cells[..n]) {
            *cell = u8::from(class == 1);
        }
        self.n_points = 0;
        true
    }

    /// Writes width, height, resolution, origin, kind = GRID_CONTACT and `cells[..w·h]` into a
    /// (loaned) message; the header and the unused tail of `cells` are left alone.
    pub fn write(&self, out: &mut Grid) {
        self.geometry.write_grid(GRID_CONTACT, &self.cells, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_abs_diff_eq;
    use mole_types::{Message, TactileReading};
    use proptest::prelude::*;
    use std::f64::consts::{FRAC_PI_2, PI, TAU};

    /// `k` sensors evenly around a rim of radius `r`, all quiet.
    fn ring(k: usize, r: f64) -> Tactile {
        let mut t: Tactile = bytemuck::Zeroable::zeroed();
        t.n_sensors = k as u32;
        t.radius = r as f32;
        for i in 0..k {
            t.sensors[i].angle = wrap_angle(i as f64 * TAU / k as f64) as f32;
        }
        t
    }

    fn push(t: &mut Tactile, i: usize, direction: f64, magnitude: f64) {
        t.sensors[i].fx = (magnitude * direction.cos()) as f32;
        t.sensors[i].fy = (magnitude * direction.sin()) as f32;
    }

    #[test]
    fn a_restored_contact_grid_has_the_published_cells() {
        let mut source = ContactGrid::new(2.0, 1.0, 0.1).unwrap();
        assert!(source.mark_occupied(0.35, 0.75));
        let mut msg: Box<Grid> = bytemuck::zeroed_box();
        source.write(&mut msg);
        let mut replacement = ContactGrid::new(2.0, 1.0, 0.1).unwrap();
        assert!(replacement.restore(&msg));
        assert_eq!(replacement.cells(), source.cells());
        msg.kind = mole_types::GRID_FRONTIER;
        assert!(!ContactGrid::new(2.0, 1.0, 0.1).unwrap().restore(&msg));
    }

    #[test]
    fn single_sensor_contact_is_on_the_rim_opposite_the_force_in_every_heading() {
        let r = 0.2;
        for heading in [0.0, 0.7, FRAC_PI_2, 2.5, PI, -1.2, -FRAC_PI_2] {
            // Sensor 1 of 8 (at π/4) feels a push along -x of the robot frame (not along
            // its own radial direction): the contact is at the robot's front, (r, 0).
            let mut t = ring(8, r);
            push(&mut t, 1, PI, 5.0);
            let mut g = ContactGrid::new(10.0, 10.0, 0.05).unwrap();
            let pose = Pose2::new(4.0, 6.0, heading);
            let pts = g.integrate_tactile(pose, &t, 1.0).to_vec();
            assert_eq!(pts.len(), 1);
            let (x, y) = pts[0];
            assert_abs_diff_eq!((x - 4.0).hypot(y - 6.0), r, epsilon = 1e-6);
            assert_abs_diff_eq!(x, 4.0 + r * heading.cos(), epsilon = 1e-6);
            assert_abs_diff_eq!(y, 6.0 + r * heading.sin(), epsilon = 1e-6);
            let expect = g.geometry().world_to_index(x, y).unwrap();
            assert_eq!(g.cells().iter().filter(|c| **c == 1).count(), 1);
            assert_eq!(g.cells()[expect], 1);
            // The same push on a sensor facing left, from the left: contact on the left side.
            let mut t = ring(8, r);
            push(&mut t, 2, -FRAC_PI_2, 5.0);
            let pts = g.integrate_tactile(pose, &t, 1.0);
            let left = heading + FRAC_PI_2;
            assert_abs_diff_eq!(pts[0].0, 4.0 + r * left.cos(), epsilon = 1e-6);
            assert_abs_diff_eq!(pts[0].1, 6.0 + r * left.sin(), epsilon = 1e-6);
        }
    }

    #[test]
    fn world_cell_after_rotation() {
        // Robot at (2.5, 2.5) facing +y, 0.5 m radius, 0.1 m cells: a push from the robot's
        // right (force along robot +y) puts the contact at robot-frame (0, -0.5), which is world
        // (+0.5, 0) of the robot: (3.03, 2.53), cell (30, 25).
        let mut t = ring(4, 0.5);
        push(&mut t, 3, FRAC_PI_2, 2.0);
        let mut g = ContactGrid::new(5.0, 5.0, 0.1).unwrap();
        let pts = g.integrate_tactile(Pose2::new(2.53, 2.53, FRAC_PI_2), &t, 0.5);
        assert_abs_diff_eq!(pts[0].0, 3.03, epsilon = 1e-6);
        assert_abs_diff_eq!(pts[0].1, 2.53, epsilon = 1e-6);
        assert_eq!(g.cells()[g.geometry().index(30, 25)], 1);
    }

    #[test]
    fn two_sensors_splitting_a_force_give_the_in_between_point() {
        let mut t = ring(16, 0.3);
        let step = TAU / 16.0;
        // Contact exactly between sensors 0 and 1, at step/2: each feels half the push.
        let normal = step / 2.0 + PI;
        push(&mut t, 0, normal, 2.0);
        push(&mut t, 1, normal, 2.0);
        let mut out = [(0.0, 0.0); MAX_TACTILE];
        assert_eq!(estimate_contacts(&t, 1.0, &mut out), 1);
        assert_abs_diff_eq!(out[0].1.atan2(out[0].0), step / 2.0, epsilon = 1e-6);
        assert_abs_diff_eq!(out[0].0.hypot(out[0].1), 0.3, epsilon = 1e-6);
        // Each sensor reading its own radial push, the stronger one pulls the contact its way.
        push(&mut t, 0, PI, 3.0);
        push(&mut t, 1, step + PI, 1.5);
        assert_eq!(estimate_contacts(&t, 1.0, &mut out), 1);
        let phi = out[0].1.atan2(out[0].0);
        assert!(phi > 0.0 && phi < step / 2.0, "{phi}");
        let expect = (1.5 * step.sin()).atan2(3.0 + 1.5 * step.cos());
        assert_abs_diff_eq!(phi, expect, epsilon = 1e-6);
    }

    #[test]
    fn separate_touches_give_separate_contacts_and_quiet_sensors_none() {
        let mut t = ring(8, 0.2);
        let mut out = [(0.0, 0.0); MAX_TACTILE];
        assert_eq!(estimate_contacts(&t, 0.1, &mut out), 0);
        // Below the threshold: nothing.
        push(&mut t, 0, PI, 0.5);
        assert_eq!(estimate_contacts(&t, 1.0, &mut out), 0);
        // A corner: front (sensor 0) and left (sensor 2), with sensor 1 quiet between them.
        push(&mut t, 0, PI, 4.0);
        push(&mut t, 2, -FRAC_PI_2, 4.0);
        assert_eq!(estimate_contacts(&t, 1.0, &mut out), 2);
        let mut angles: Vec<f64> = out[..2].iter().map(|p| p.1.atan2(p.0)).collect();
        angles.sort_by(f64::total_cmp);
        assert_abs_diff_eq!(angles[0], 0.0, epsilon = 1e-6);
        assert_abs_diff_eq!(angles[1], FRAC_PI_2, epsilon = 1e-6);
        // A run across the ±π seam (sensors at 3π/4 and -3π/4) is one contact, at π.
        let mut t = ring(8, 0.2);
        push(&mut t, 3, -PI / 4.0, 2.0);
        push(&mut t, 5, PI / 4.0, 2.0);
        push(&mut t, 4, 0.0, 2.0);
        assert_eq!(estimate_contacts(&t, 1.0, &mut out), 1);
        assert_abs_diff_eq!(out[0].1.atan2(out[0].0).abs(), PI, epsilon = 1e-6);
        // Every sensor touching with forces that cancel: no contact; that do not: one.
        let mut t = ring(4, 0.2);
        for i in 0..4 {
            push(&mut t, i, i as f64 * FRAC_PI_2 + PI, 2.0);
        }
        assert_eq!(estimate_contacts(&t, 1.0, &mut out), 0);
        push(&mut t, 0, PI, 5.0);
        assert_eq!(estimate_contacts(&t, 1.0, &mut out), 1);
        assert_abs_diff_eq!(out[0].1.atan2(out[0].0), 0.0, epsilon = 1e-6);
    }

    #[test]
    fn bad_input_is_ignored() {
        let mut g = ContactGrid::new(5.0, 5.0, 0.1).unwrap();
        let mut t = ring(8, 0.2);
        push(&mut t, 0, PI, 4.0);
        for pose in [
            Pose2::new(f64::NAN, 1.0, 0.0),
            Pose2::new(1.0, 1.0, f64::INFINITY),
        ] {
            assert!(g.integrate_tactile(pose, &t, 1.0).is_empty());
        }
        // Contact outside the arena: not marked, not returned.
        assert!(
            g.integrate_tactile(Pose2::new(4.9, 1.0, 0.0), &t, 1.0)
                .is_empty()
        );
        let here = Pose2::new(2.0, 2.0, 0.0);
        assert!(g.integrate_tactile(here, &t, f64::NAN).is_empty());
        let mut bad = t;
        bad.radius = f32::NAN;
        assert!(g.integrate_tactile(here, &bad, 1.0).is_empty());
        bad.radius = -0.2;
        assert!(g.integrate_tactile(here, &bad, 1.0).is_empty());
        let mut bad = t;
        bad.sensors[0].fx = f32::NAN;
        assert!(g.integrate_tactile(here, &bad, 1.0).is_empty());
        let mut bad = t;
        bad.n_sensors = u32::MAX;
        assert_eq!(g.integrate_tactile(here, &bad, 1.0).len(), 1);
        assert_eq!(g.cells().iter().filter(|c| **c == 1).count(), 1);
        assert_eq!(g.contacts().len(), 1);
    }

    #[test]
    fn write_fills_the_message_but_not_the_header() {
        let mut g = ContactGrid::new(3.0, 2.0, 0.5).unwrap();
        g.mark_occupied(1.2, 0.7);
        let mut out: Box<Grid> = bytemuck::zeroed_box();
        out.header.tick = 9;
        g.write(&mut out);
        assert_eq!(out.header.tick, 9);
        assert_eq!((out.width, out.height, out.kind), (6, 4, GRID_CONTACT));
        assert_eq!(out.cells(), g.cells());
        assert_eq!(out.cells[g.geometry().index(2, 1)], 1);
        assert_eq!(out.validate(), Ok(()));
    }

    fn any_f32() -> impl Strategy<Value = f32> {
        prop_oneof![
            8 => -10.0..10.0f32,
            1 => Just(f32::NAN),
            1 => Just(f32::INFINITY),
            1 => Just(0.0f32),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        /// Every cell stays in {0, 1}; every returned point is on the rim and marked.
        #[test]
        fn cells_stay_binary_and_points_on_the_rim(
            x in -1.0..7.0f64, y in -1.0..6.0f64, theta in -10.0..10.0f64,
            radius in prop_oneof![4 => 0.05..0.5f32, 1 => any_f32()],
            threshold in prop_oneof![4 => 0.0..3.0f64, 1 => Just(f64::NAN), 1 => Just(-1.0)],
            readings in prop::collection::vec((any_f32(), any_f32(), any_f32()), 0..40),
        ) {
            let mut t: Tactile = bytemuck::Zeroable::zeroed();
            t.radius = radius;
            t.n_sensors = readings.len() as u32;
            for (s, (a, fx, fy)) in t.sensors.iter_mut().zip(&readings) {
                *s = TactileReading { angle: *a, fx: *fx, fy: *fy, _pad: 0.0 };
            }
            let mut g = ContactGrid::new(6.0, 5.0, 0.2).unwrap();
            let pts = g.integrate_tactile(Pose2::new(x, y, theta), &t, threshold).to_vec();
            prop_assert!(pts.len() <= MAX_TACTILE);
            for (px, py) in &pts {
                prop_assert!(((px - x).hypot(py - y) - radius as f64).abs() < 1e-6);
                let idx = g.geometry().world_to_index(*px, *py);
                prop_assert!(idx.is_some_and(|i| g.cells()[i] == 1));
            }
            prop_assert!(g.cells().iter().all(|c| *c <= 1));
            prop_assert!(g.cells().iter().filter(|c| **c == 1).count() <= pts.len());
            let mut out: Box<Grid> = bytemuck::zeroed_box();
            g.write(&mut out);
            prop_assert_eq!(out.validate(), Ok(()));
        }
    }
}
