//! What the planners read from the sensors: the obstacle distance d_obs of algorithms §4 from a scan,
//! contact from the tactile forces, the freest direction, and free-space checks against a scan
//! or the frontier grid (algorithms §5.2 cell codes). Pure functions; none allocates.
//!
//! Bad values in a message (a non-finite or negative range, a non-finite angle or force, a grid
//! with a bad resolution) are skipped, never trusted: a skipped beam sees nothing.

use mole_types::{CELL_OCCUPIED, Grid, Scan, Tactile, wrap_angle};

/// Angle of beam `i` relative to the heading (rad): `angle_min + i·angle_increment`.
#[inline]
pub fn beam_angle(scan: &Scan, i: usize) -> f64 {
    scan.angle_min as f64 + i as f64 * scan.angle_increment as f64
}

/// The beams worth reading: none if the angle fields are not finite.
#[inline]
fn usable_ranges(scan: &Scan) -> &[f32] {
    if (scan.angle_min as f64).is_finite() && (scan.angle_increment as f64).is_finite() {
        scan.ranges()
    } else {
        &[]
    }
}

/// The nearest obstacle a scan sees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Nearest {
    /// d_obs: range minus the robot radius (m); negative when overlapping.
    pub d_obs: f64,
    /// Beam angle relative to the heading (rad).
    pub angle: f64,
}

/// Algorithms §4: d_obs = min over the beams within `half_angle` of `direction` (robot frame) of
/// range − radius; `None` when no beam is in the sector. `half_angle ≥ π` takes every beam,
/// the source's form; a sector around the direction of travel keeps walls beside or behind the
/// robot, which it is not moving toward, from triggering.
pub fn nearest_obstacle(
    scan: &Scan,
    radius: f64,
    direction: f64,
    half_angle: f64,
) -> Option<Nearest> {
    let mut best: Option<Nearest> = None;
    for (i, &r) in usable_ranges(scan).iter().enumerate() {
        let r = r as f64;
        if !(r.is_finite() && r >= 0.0) {
            continue;
        }
        let a = beam_angle(scan, i);
        if half_angle < core::f64::consts::PI && wrap_angle(a - direction).abs() > half_angle {
            continue;
        }
        let d = r - radius;
        if best.is_none_or(|b| d < b.d_obs) {
            best = Some(Nearest {
                d_obs: d,
                angle: wrap_angle(a),
            });
        }
    }
    best
}

/// The net force (robot frame, N) of the tactile sensors whose |f| exceeds `threshold`, or
/// `None` when no sensor does (algorithms §4: touch is the trigger of last resort).
pub fn contact_force(tactile: &Tactile, threshold: f64) -> Option<[f64; 2]> {
    let mut net: Option<[f64; 2]> = None;
    for s in tactile.sensors() {
        let (fx, fy) = (s.fx as f64, s.fy as f64);
        let magnitude = fx.hypot(fy);
        if magnitude.is_finite() && magnitude > threshold {
            let n = net.get_or_insert([0.0; 2]);
            n[0] += fx;
            n[1] += fy;
        }
    }
    net
}

/// The freest direction of a scan (robot frame, rad): the beam whose neighbourhood of
/// ±`window` rad has the largest minimum range; among equals, the one farthest from `avoid`
/// (the obstacle side). `None` without usable beams.
pub fn freest_direction(scan: &Scan, window: f64, avoid: f64) -> Option<f64> {
    let ranges = usable_ranges(scan);
    let inc = (scan.angle_increment as f64).abs();
    let w = if inc > 0.0 {
        (window.max(0.0) / inc).floor().min(ranges.len() as f64) as usize
    } else {
        0
    };
    let full_circle = inc * ranges.len() as f64 >= core::f64::consts::TAU - 1e-6;
    let n = ranges.len();
    let mut best: Option<(f64, f64, f64)> = None; // (score, distance from avoid, angle)
    for i in 0..n {
        let mut score = f64::INFINITY;
        let lo = i as isize - w as isize;
        let hi = i as isize + w as isize;
        for j in lo..=hi {
            let j = if full_circle {
                j.rem_euclid(n as isize) as usize
            } else if j < 0 || j >= n as isize {
                continue;
            } else {
                j as usize
            };
            let r = ranges[j] as f64;
            score = score.min(if r.is_finite() && r >= 0.0 { r } else { 0.0 });
        }
        let a = wrap_angle(beam_angle(scan, i));
        let away = wrap_angle(a - avoid).abs();
        let better = match best {
            None => true,
            Some((s, d, _)) => score > s + 1e-9 || ((score - s).abs() <= 1e-9 && away > d),
        };
        if better {
            best = Some((score, away, a));
        }
    }
    best.map(|(_, _, a)| a)
}

/// Whether the straight corridor from the robot along `direction` (robot frame), `length` long
/// and `half_width` to each side, holds no scan hit. Beams that read `range_max` hit nothing.
pub fn corridor_clear(scan: &Scan, direction: f64, length: f64, half_width: f64) -> bool {
    let range_max = scan.range_max as f64;
    for (i, &r) in usable_ranges(scan).iter().enumerate() {
        let r = r as f64;
        if !(r.is_finite() && r >= 0.0) || r >= range_max {
            continue;
        }
        let (s, c) = wrap_angle(beam_angle(scan, i) - direction).sin_cos();
        let (along, lateral) = (r * c, r * s);
        if along > 0.0 && along < length && lateral.abs() < half_width {
            return false;
        }
    }
    true
}

/// How far (m) a disk of radius `radius` can move from the robot along `direction` (robot
/// frame) before it touches a scan hit: min over the hits in its path of
/// along − √(radius² − lateral²); ∞ when the path holds no hit.
pub fn free_travel(scan: &Scan, direction: f64, radius: f64) -> f64 {
    let range_max = scan.range_max as f64;
    let mut free = f64::INFINITY;
    for (i, &r) in usable_ranges(scan).iter().enumerate() {
        let r = r as f64;
        if !(r.is_finite() && r >= 0.0) || r >= range_max {
            continue;
        }
        let (s, c) = wrap_angle(beam_angle(scan, i) - direction).sin_cos();
        let (along, lateral) = (r * c, r * s);
        if along > -radius && lateral.abs() < radius {
            free = free.min(along - (radius * radius - lateral * lateral).sqrt());
        }
    }
    free
}

/// The cell value of a grid at world point (x, y); `None` outside the grid or when the grid's
/// geometry is unusable.
pub fn grid_cell(grid: &Grid, x: f64, y: f64) -> Option<u8> {
    let res = grid.resolution;
    if !(res.is_finite() && res > 0.0 && grid.origin_x.is_finite() && grid.origin_y.is_finite()) {
        return None;
    }
    let col = ((x - grid.origin_x) / res).floor();
    let row = ((y - grid.origin_y) / res).floor();
    if !(col >= 0.0 && row >= 0.0 && col < grid.width as f64 && row < grid.height as f64) {
        return None;
    }
    grid.cells()
        .get(row as usize * grid.width as usize + col as usize)
        .copied()
}

/// Whether every cell along the segment from `from` to `to` is free (1) or unexplored (0) and
/// inside the grid: never occupied (2), never off the map.
pub fn segment_free(grid: &Grid, from: [f64; 2], to: [f64; 2]) -> bool {
    let res = grid.resolution;
    if !(res.is_finite() && res > 0.0) {
        return false;
    }
    let (dx, dy) = (to[0] - from[0], to[1] - from[1]);
    let len = dx.hypot(dy);
    if !len.is_finite() {
        return false;
    }
    // Half a cell per sample: no cell the segment crosses by more than a corner is skipped.
    let n = (len / (0.5 * res)).ceil().min(1e6) as usize;
    (0..=n).all(|k| {
        let t = if n == 0 { 0.0 } else { k as f64 / n as f64 };
        matches!(grid_cell(grid, from[0] + t * dx, from[1] + t * dy), Some(c) if c < CELL_OCCUPIED)
    })
}

#[cfg(test)]
pub(crate) mod test_support {
    use mole_types::{GRID_FRONTIER, Grid, Scan};

    /// A full-circle scan of `n` beams, all reading `range`.
    pub fn scan_uniform(n: usize, range: f32, range_max: f32) -> Box<Scan> {
        let mut s: Box<Scan> = bytemuck::zeroed_box();
        s.n_beams = n as u32;
        s.angle_min = -core::f32::consts::PI;
        s.angle_increment = core::f32::consts::TAU / n as f32;
        s.range_max = range_max;
        s.ranges[..n].fill(range);
        s
    }

    /// A full-circle scan of a wall perpendicular to the heading, `distance` ahead of the centre.
    pub fn scan_wall_ahead(n: usize, distance: f64, range_max: f32) -> Box<Scan> {
        let mut s = scan_uniform(n, range_max, range_max);
        for i in 0..n {
            let a = super::beam_angle(&s, i);
            let c = a.cos();
            if c > 1e-9 {
                s.ranges[i] = ((distance / c) as f32).min(range_max);
            }
        }
        s
    }

    /// An all-free frontier grid of `w × h` cells of `res` m with its origin at (0, 0).
    pub fn grid_free(w: u32, h: u32, res: f64) -> Box<Grid> {
        let mut g: Box<Grid> = bytemuck::zeroed_box();
        g.width = w;
        g.height = h;
        g.resolution = res;
        g.kind = GRID_FRONTIER;
        g.cells[..(w * h) as usize].fill(mole_types::CELL_FREE);
        g
    }
}

#[cfg(test)]
mod tests {
    use super::test_support::*;
    use super::*;
    use core::f64::consts::{FRAC_PI_2, PI};
    use mole_types::CELL_UNEXPLORED;

    #[test]
    fn d_obs_of_a_wall_ahead_is_its_distance_minus_radius() {
        let s = scan_wall_ahead(360, 0.5, 4.0);
        let n = nearest_obstacle(&s, 0.2, 0.0, FRAC_PI_2).map(|n| (n.d_obs, n.angle));
        let (d, a) = n.unwrap_or((f64::NAN, f64::NAN));
        assert!((d - 0.3).abs() < 1e-6 && a.abs() < 1e-6, "{d} {a}");
        // Looking backwards, only the far (range_max) beams remain.
        let back = nearest_obstacle(&s, 0.2, PI, FRAC_PI_2).map(|n| n.d_obs);
        assert!(back.is_some_and(|d| d > 1.0), "{back:?}");
        // The source's form takes every beam.
        let all = nearest_obstacle(&s, 0.2, PI, PI).map(|n| n.d_obs);
        assert!(all.is_some_and(|d| (d - 0.3).abs() < 1e-6));
    }

    #[test]
    fn bad_beams_are_skipped() {
        let mut s = scan_uniform(8, 2.0, 4.0);
        s.ranges[3] = f32::NAN;
        s.ranges[4] = -1.0;
        let d = nearest_obstacle(&s, 0.0, 0.0, PI).map(|n| n.d_obs);
        assert_eq!(d, Some(2.0));
        s.angle_increment = f32::NAN;
        assert_eq!(nearest_obstacle(&s, 0.0, 0.0, PI), None);
        assert_eq!(freest_direction(&s, 0.1, 0.0), None);
        assert!(corridor_clear(&s, 0.0, 10.0, 1.0));
    }

    #[test]
    fn freest_direction_turns_away_from_the_wall() {
        let s = scan_wall_ahead(180, 0.3, 4.0);
        let a = freest_direction(&s, 0.26, 0.0).unwrap_or(0.0);
        assert!(a.abs() > 0.9 * PI, "{a}");
        // A gap at +90°: the only long-range beams are there.
        let mut s = scan_uniform(180, 1.0, 4.0);
        for i in 40..50 {
            s.ranges[i] = 3.5;
        }
        let a = freest_direction(&s, 0.05, 0.0).unwrap_or(0.0);
        assert!(a >= beam_angle(&s, 40) && a <= beam_angle(&s, 49), "{a}");
    }

    #[test]
    fn corridor_sees_the_wall_only_where_it_is() {
        let s = scan_wall_ahead(360, 1.0, 4.0);
        assert!(!corridor_clear(&s, 0.0, 1.2, 0.2));
        assert!(corridor_clear(&s, 0.0, 0.9, 0.2));
        assert!(corridor_clear(&s, PI, 3.0, 0.2));
        // 45° off: the wall is at 1/cos45 ≈ 1.41 m along that line.
        assert!(corridor_clear(&s, PI / 4.0, 1.3, 0.05));
        assert!(!corridor_clear(&s, PI / 4.0, 1.5, 0.05));
    }

    #[test]
    fn free_travel_ignores_walls_beside_the_path() {
        let s = scan_wall_ahead(360, 1.0, 4.0);
        assert!(
            (free_travel(&s, 0.0, 0.2) - 0.8).abs() < 1e-3,
            "{}",
            free_travel(&s, 0.0, 0.2)
        );
        // Along the wall (it is 1 m to the side): nothing in the path.
        assert_eq!(free_travel(&s, FRAC_PI_2, 0.2), f64::INFINITY);
        assert_eq!(free_travel(&s, PI, 0.2), f64::INFINITY);
    }

    #[test]
    fn contact_force_sums_sensors_above_threshold() {
        let mut t: Box<Tactile> = bytemuck::zeroed_box();
        t.n_sensors = 4;
        t.sensors[0].fx = -3.0;
        t.sensors[1].fx = -1.0;
        t.sensors[1].fy = 0.1;
        t.sensors[2].fy = 0.2; // below threshold
        t.sensors[3].fx = f32::NAN;
        assert_eq!(contact_force(&t, 0.5), Some([-4.0, 0.1f32 as f64]));
        assert_eq!(contact_force(&t, 5.0), None);
        t.n_sensors = 0;
        assert_eq!(contact_force(&t, 0.0), None);
    }

    #[test]
    fn segments_through_occupied_or_outside_cells_are_not_free() {
        let mut g = grid_free(20, 20, 0.1);
        g.cells[5 * 20 + 10] = CELL_OCCUPIED; // cell (col 10, row 5): x ∈ [1.0, 1.1), y ∈ [0.5, 0.6)
        g.cells[15 * 20 + 3] = CELL_UNEXPLORED;
        assert_eq!(grid_cell(&g, 1.05, 0.55), Some(CELL_OCCUPIED));
        assert_eq!(grid_cell(&g, -0.01, 0.5), None);
        assert!(!segment_free(&g, [0.5, 0.55], [1.5, 0.55]));
        assert!(segment_free(&g, [0.5, 0.75], [1.5, 0.75]));
        assert!(
            segment_free(&g, [0.35, 1.0], [0.35, 1.9]),
            "unexplored counts as free"
        );
        assert!(
            !segment_free(&g, [1.5, 1.5], [2.5, 1.5]),
            "off the map is not free"
        );
        g.resolution = 0.0;
        assert!(!segment_free(&g, [0.5, 0.75], [1.5, 0.75]));
    }
}
