//! The frontier grid of algorithms §5.2 (0 unexplored, 1 free, 2 occupied), estimated as an occupancy
//! grid in log-odds (Thrun, Burgard & Fox, *Probabilistic Robotics*, §9.2, Table 9.1).

use crate::{GridGeometry, MappingError};
use mole_types::Setting;
use mole_types::{CELL_FREE, CELL_OCCUPIED, CELL_UNEXPLORED, GRID_FRONTIER, Grid, Pose2, Scan};
use serde::{Deserialize, Serialize};

/// The log-odds increments and bounds of the inverse sensor models.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Setting)]
#[serde(default, deny_unknown_fields)]
#[setting(check = LogOddsParams::check_setting)]
pub struct LogOddsParams {
    /// Increment for the cell a beam ends in: log(0.7/0.3) (Probabilistic Robotics §9.2, l_occ).
    #[setting(above = 0.0)]
    pub hit: f32,
    /// Increment for a cell a beam passes through: log(0.4/0.6) (Probabilistic Robotics §9.2, l_free).
    #[setting(max = 0.0)]
    pub miss: f32,
    /// Increment for a touched cell: saturating, so that one touch makes a cell occupied and
    /// takes lidar passes to undo (touch is the most direct evidence there is).
    #[setting(above = 0.0)]
    pub touch: f32,
    /// Increment for a cell under the robot's disk.
    #[setting(max = 0.0)]
    pub footprint: f32,
    /// Lower clamp of the log-odds (Probabilistic Robotics §9.2: bounded so the map can recover).
    #[setting(max = 0.0)]
    pub min: f32,
    /// Upper clamp of the log-odds.
    #[setting(above = 0.0)]
    pub max: f32,
    /// A cell is unexplored while |l| < threshold, else free (l < 0) or occupied (l > 0).
    #[setting(above = 0.0)]
    pub threshold: f32,
    /// How far past the measured range the hit point is taken, in cells; 0.5 marks the cell whose
    /// centre lies behind the surface (for a beam along an axis), so a surface on a cell edge is
    /// not split by the range noise between the two cells beside it.
    #[setting(min = 0.0)]
    pub hit_depth_cells: f64,
}

impl Default for LogOddsParams {
    fn default() -> Self {
        Self {
            hit: 0.847,
            miss: -0.405,
            touch: 8.0,
            footprint: -0.405,
            min: -2.0,
            max: 3.5,
            threshold: 0.3,
            hit_depth_cells: 0.5,
        }
    }
}

impl LogOddsParams {
    /// Checks that every increment has its sign and one observation of each kind is decisive.
    pub fn check(&self) -> Result<(), MappingError> {
        let all_finite = [
            self.hit,
            self.miss,
            self.touch,
            self.footprint,
            self.min,
            self.max,
            self.threshold,
        ]
        .iter()
        .all(|v| v.is_finite())
            && self.hit_depth_cells.is_finite();
        if !all_finite {
            return Err(MappingError::InvalidParams("a parameter is not finite"));
        }
        if !(self.min < 0.0 && self.max > 0.0) {
            return Err(MappingError::InvalidParams("need min < 0 < max"));
        }
        if !(self.threshold > 0.0 && self.threshold < self.max && self.threshold < -self.min) {
            return Err(MappingError::InvalidParams(
                "need 0 < threshold < min(max, -min)",
            ));
        }
        if !(self.hit > 0.0 && self.touch > 0.0 && self.miss < 0.0 && self.footprint < 0.0) {
            return Err(MappingError::InvalidParams(
                "need hit, touch > 0 and miss, footprint < 0",
            ));
        }
        if !(0.0..=1.0).contains(&self.hit_depth_cells) {
            return Err(MappingError::InvalidParams(
                "need 0 <= hit_depth_cells <= 1",
            ));
        }
        Ok(())
    }

    /// [`LogOddsParams::check`] as a setting's check.
    fn check_setting(&self) -> Result<(), mole_types::settings::SettingError> {
        self.check().map_err(|e| {
            mole_types::settings::SettingError::new("", &e.to_string(), &"these log-odds")
        })
    }

    /// Algorithms §5.2's cell value for log-odds `l`.
    #[inline]
    pub fn classify(&self, l: f32) -> u8 {
        if l >= self.threshold {
            CELL_OCCUPIED
        } else if l <= -self.threshold {
            CELL_FREE
        } else {
            CELL_UNEXPLORED
        }
    }
}

/// No update for this cell in the current scan.
const MARK_NONE: u8 = 0;
/// A beam passed through this cell in the current scan.
const MARK_MISS: u8 = 1;
/// A beam ended in this cell in the current scan.
const MARK_HIT: u8 = 2;

/// Occupancy by log-odds with ray traversal (Thrun, Probabilistic Robotics §9.2, inverse sensor
/// model), thresholded to algorithms §5.2's 0/1/2.
#[derive(Debug, Clone)]
pub struct FrontierGrid {
    geometry: GridGeometry,
    params: LogOddsParams,
    /// l_t,i per cell (Probabilistic Robotics eq. 9.7's log-odds, prior 0).
    log_odds: Vec<f32>,
    /// Algorithms §5.2's M_t, kept in step with `log_odds`.
    cells: Vec<u8>,
    /// Per-cell update of the scan being integrated (MARK_*), all MARK_NONE between scans.
    marks: Vec<u8>,
    /// Cells marked in the current scan; capacity = cell count, so pushing never allocates.
    touched: Vec<u32>,
}

impl FrontierGrid {
    /// An all-unexplored grid over the arena `[0, width_m] × [0, height_m]`, default parameters.
    pub fn new(width_m: f64, height_m: f64, resolution: f64) -> Result<FrontierGrid, MappingError> {
        Self::with_params(width_m, height_m, resolution, LogOddsParams::default())
    }

    /// As [`FrontierGrid::new`] with explicit log-odds parameters.
    pub fn with_params(
        width_m: f64,
        height_m: f64,
        resolution: f64,
        params: LogOddsParams,
    ) -> Result<FrontierGrid, MappingError> {
        params.check()?;
        let geometry = GridGeometry::for_arena(width_m, height_m, resolution)?;
        let n = geometry.len();
        Ok(Self {
            geometry,
            params,
            log_odds: vec![0.0; n],
            cells: vec![CELL_UNEXPLORED; n],
            marks: vec![MARK_NONE; n],
            touched: Vec::with_capacity(n),
        })
    }

    /// The grid's size and placement.
    pub fn geometry(&self) -> &GridGeometry {
        &self.geometry
    }

    /// The log-odds parameters in use.
    pub fn params(&self) -> &LogOddsParams {
        &self.params
    }

    /// New log-odds parameters from the next update on (`mole param set`); the cells keep
    /// their log-odds, clamped into the new bounds as they are next updated.
    pub fn set_params(&mut self, params: LogOddsParams) -> Result<(), MappingError> {
        params.check()?;
        self.params = params;
        Ok(())
    }

    /// Algorithms §5.2's cells (0 unexplored, 1 free, 2 occupied), row-major, maintained incrementally.
    pub fn cells(&self) -> &[u8] {
        &self.cells
    }

    /// The log-odds of every cell, row-major.
    pub fn log_odds(&self) -> &[f32] {
        &self.log_odds
    }

    /// Forgets everything: every cell unexplored again.
    pub fn clear(&mut self) {
        self.log_odds.fill(0.0);
        self.cells.fill(CELL_UNEXPLORED);
    }

    /// Integrate one scan taken at `pose` (estimated): every cell along each beam up to the hit
    /// gets the free update, the hit cell the occupied update unless the range is >= range_max
    /// (Probabilistic Robotics §9.2, Table 9.2, with exact traversal instead of a cone).
    ///
    /// Each cell gets at most one update per scan, occupied winning over free, as Table 9.1 does
    /// (one inverse-sensor-model value per cell and scan): otherwise a wall seen at a grazing
    /// angle would be erased by the neighbouring beams that pass through its cells. Beams with a
    /// non-finite or non-positive range are skipped; a pose outside the grid or a scan with
    /// non-finite angles or range_max is ignored; hits outside the grid are dropped.
    pub fn integrate_scan(&mut self, pose: Pose2, scan: &Scan) {
        if !(pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite()) {
            return;
        }
        if self.geometry.world_to_cell(pose.x, pose.y).is_none() {
            return;
        }
        let angle_min = scan.angle_min as f64;
        let angle_increment = scan.angle_increment as f64;
        let range_max = scan.range_max as f64;
        if !(angle_min.is_finite() && angle_increment.is_finite() && range_max.is_finite()) {
            return;
        }
        if range_max <= 0.0 {
            return;
        }
        let depth = self.params.hit_depth_cells * self.geometry.resolution;
        // The end of beam i and whether it is a hit, or None for an unusable reading.
        let beam_end = |i: usize, range: f32| -> Option<(f64, f64, bool)> {
            let range = range as f64;
            if !(range.is_finite() && range > 0.0) {
                return None;
            }
            let hit = range < range_max;
            let reach = if hit { range + depth } else { range_max };
            let (s, c) = (pose.theta + angle_min + i as f64 * angle_increment).sin_cos();
            Some((pose.x + reach * c, pose.y + reach * s, hit))
        };

        // Pass 1: the hit cells.
        for (i, &range) in scan.ranges().iter().enumerate() {
            let Some((x, y, true)) = beam_end(i, range) else {
                continue;
            };
            if let Some(idx) = self.geometry.world_to_index(x, y) {
                if self.marks[idx] == MARK_NONE {
                    self.touched.push(idx as u32);
                }
                self.marks[idx] = MARK_HIT;
            }
        }
        // Pass 2: the cells the beams pass through.
        let geometry = self.geometry;
        for (i, &range) in scan.ranges().iter().enumerate() {
            let Some((x, y, _)) = beam_end(i, range) else {
                continue;
            };
            let (marks, touched) = (&mut self.marks, &mut self.touched);
            geometry.traverse(pose.x, pose.y, x, y, |col, row| {
                let idx = geometry.index(col, row);
                if marks[idx] == MARK_NONE {
                    marks[idx] = MARK_MISS;
                    touched.push(idx as u32);
                }
            });
        }
        // Apply: one update per touched cell (Probabilistic Robotics eq. 9.7 with l_0 = 0).
        let p = self.params;
        for &idx in &self.touched {
            let idx = idx as usize;
            let delta = if self.marks[idx] == MARK_HIT {
                p.hit
            } else {
                p.miss
            };
            self.marks[idx] = MARK_NONE;
            let l = (self.log_odds[idx] + delta).clamp(p.min, p.max);
            self.log_odds[idx] = l;
            self.cells[idx] = p.classify(l);
        }
        self.touched.clear();
    }

    /// Cells under the robot's disk are free (the robot is there): every cell whose centre lies
    /// within `radius` of the position, and the cell holding the position. This is how the map
    /// grows when there is no lidar.
    ///
    /// A cell that is occupied now is left alone: the rim touches obstacles, so the cells of its
    /// contacts lie half under the disk, and touch beats the footprint (lidar can still clear
    /// them). A non-finite position or radius, or a negative radius, is ignored.
    pub fn integrate_footprint(&mut self, pose: Pose2, radius: f64) {
        if !(pose.x.is_finite() && pose.y.is_finite() && radius.is_finite() && radius >= 0.0) {
            return;
        }
        let g = self.geometry;
        let (gx, gy) = g.to_grid(pose.x, pose.y);
        let gr = radius / g.resolution;
        // Bounding box of the disk in cells, clamped to the grid.
        let (w, h) = (g.width as f64, g.height as f64);
        if gx + gr < 0.0 || gy + gr < 0.0 || gx - gr > w || gy - gr > h {
            return;
        }
        let lo = |v: f64, n: f64| (v.floor().max(0.0).min(n - 1.0)) as u32;
        let (c0, c1) = (lo(gx - gr, w), lo(gx + gr, w));
        let (r0, r1) = (lo(gy - gr, h), lo(gy + gr, h));
        let r2 = gr * gr;
        let centre = g.world_to_index(pose.x, pose.y);
        for row in r0..=r1 {
            for col in c0..=c1 {
                let (dx, dy) = (col as f64 + 0.5 - gx, row as f64 + 0.5 - gy);
                let idx = g.index(col, row);
                if dx * dx + dy * dy <= r2 || centre == Some(idx) {
                    self.update_footprint(idx);
                }
            }
        }
    }

    fn update_footprint(&mut self, idx: usize) {
        let p = &self.params;
        if self.cells[idx] == CELL_OCCUPIED {
            return;
        }
        let l = (self.log_odds[idx] + p.footprint).clamp(p.min, p.max);
        self.log_odds[idx] = l;
        self.cells[idx] = p.classify(l);
    }

    /// A touched point is occupied (strong occupied update), so touch alone also builds the
    /// frontier grid. A point outside the grid or not finite is ignored.
    pub fn mark_occupied(&mut self, x: f64, y: f64) {
        let Some(idx) = self.geometry.world_to_index(x, y) else {
            return;
        };
        let p = &self.params;
        let l = (self.log_odds[idx] + p.touch).clamp(p.min, p.max);
        self.log_odds[idx] = l;
        self.cells[idx] = p.classify(l);
    }

    /// Takes over a frontier grid published by the mapping process being replaced (a hot
    /// swap); returns false, changing nothing, for a grid of another kind or geometry. The
    /// message carries classes, not log-odds: a free cell restarts halfway between the
    /// threshold and the lower clamp, an occupied one halfway to the upper clamp, so the map
    /// neither flips on the first contrary reading nor holds out like a saturated cell.
    pub fn restore(&mut self, grid: &Grid) -> bool {
        if grid.kind != GRID_FRONTIER || !self.geometry.matches(grid) {
            return false;
        }
        let p = self.params;
        let free = 0.5 * (p.min - p.threshold);
        let occupied = 0.5 * (p.max + p.threshold);
        for ((l, cell), &class) in self
            .log_odds
            .iter_mut()
            .zip(self.cells.iter_mut())
            .zip(&grid.cells[..self.geometry.len()])
        {
            *l = match class {
                CELL_FREE => free,
                CELL_OCCUPIED => occupied,
                _ => 0.0,
            };
            *cell = p.classify(*l);
        }
        true
    }

    /// Writes width, height, resolution, origin, kind = GRID_FRONTIER and `cells[..w·h]` into a
    /// (loaned) message; the header and the unused tail of `cells` are left alone.
    pub fn write(&self, out: &mut Grid) {
        self.geometry.write_grid(GRID_FRONTIER, &self.cells, out);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mole_types::{MAX_BEAMS, Message};
    use proptest::prelude::*;
    use std::f64::consts::{FRAC_PI_2, PI, TAU};

    fn scan(angle_min: f64, angle_increment: f64, range_max: f64, ranges: &[f64]) -> Box<Scan> {
        let mut s: Box<Scan> = bytemuck::zeroed_box();
        s.angle_min = angle_min as f32;
        s.angle_increment = angle_increment as f32;
        s.range_max = range_max as f32;
        s.n_beams = ranges.len() as u32;
        for (d, r) in s.ranges.iter_mut().zip(ranges) {
            *d = *r as f32;
        }
        s
    }

    fn cell(g: &FrontierGrid, col: u32, row: u32) -> u8 {
        g.cells()[g.geometry().index(col, row)]
    }

    fn count(g: &FrontierGrid, v: u8) -> usize {
        g.cells().iter().filter(|c| **c == v).count()
    }

    #[test]
    fn a_restored_grid_has_the_published_classes_and_refuses_other_geometries() {
        let mut source = FrontierGrid::new(2.0, 1.0, 0.1).unwrap();
        source.mark_occupied(0.55, 0.55);
        source.integrate_footprint(Pose2::new(1.5, 0.5, 0.0), 0.2);
        let mut msg: Box<Grid> = bytemuck::zeroed_box();
        source.write(&mut msg);
        let mut replacement = FrontierGrid::new(2.0, 1.0, 0.1).unwrap();
        assert!(replacement.restore(&msg));
        assert_eq!(replacement.cells(), source.cells());
        let p = LogOddsParams::default();
        let idx = replacement.geometry().world_to_index(0.55, 0.55).unwrap();
        assert!(replacement.log_odds()[idx] > p.threshold && replacement.log_odds()[idx] < p.max);
        let mut other = FrontierGrid::new(2.0, 1.0, 0.05).unwrap();
        assert!(!other.restore(&msg), "another resolution");
        assert!(other.cells().iter().all(|&c| c == CELL_UNEXPLORED));
        msg.kind = mole_types::GRID_CONTACT;
        assert!(!replacement.restore(&msg), "a contact grid");
    }

    #[test]
    fn beam_along_a_row_marks_free_cells_then_the_hit() {
        let mut g = FrontierGrid::new(10.0, 10.0, 1.0).unwrap();
        // Robot in cell (1, 4), facing +x; wall 4.8 m ahead, at x = 6.3 (inside cell 6).
        let s = scan(0.0, 0.0, 8.0, &[4.8]);
        g.integrate_scan(Pose2::new(1.5, 4.5, 0.0), &s);
        for col in 1..=5 {
            assert_eq!(cell(&g, col, 4), CELL_FREE, "col {col}");
        }
        assert_eq!(cell(&g, 6, 4), CELL_OCCUPIED);
        assert_eq!(count(&g, CELL_FREE), 5);
        assert_eq!(count(&g, CELL_OCCUPIED), 1);
        let l = g.log_odds()[g.geometry().index(6, 4)];
        assert!((l - 0.847).abs() < 1e-6);
        let l = g.log_odds()[g.geometry().index(3, 4)];
        assert!((l + 0.405).abs() < 1e-6);
        // Beam angles are relative to the heading: θ = -π/2 plus a beam at π points along +y.
        let mut g = FrontierGrid::new(10.0, 10.0, 1.0).unwrap();
        let s = scan(PI, 0.0, 8.0, &[2.8]);
        g.integrate_scan(Pose2::new(4.5, 1.5, -FRAC_PI_2), &s);
        // Cells (4,1)..(4,3) free, (4,4) hit (y = 4.3).
        for row in 1..=3 {
            assert_eq!(cell(&g, 4, row), CELL_FREE, "row {row}");
        }
        assert_eq!(cell(&g, 4, 4), CELL_OCCUPIED);
    }

    #[test]
    fn a_wall_on_a_cell_edge_lands_in_the_cell_behind_it() {
        // Wall at x = 6.0 exactly (edge of cells 5 and 6), range noise around it.
        for noise in [-0.2, -0.01, 0.0, 0.01, 0.2] {
            let mut g = FrontierGrid::new(10.0, 10.0, 1.0).unwrap();
            g.integrate_scan(
                Pose2::new(1.5, 4.5, 0.0),
                &scan(0.0, 0.0, 8.0, &[4.5 + noise]),
            );
            assert_eq!(cell(&g, 5, 4), CELL_FREE, "noise {noise}");
            assert_eq!(cell(&g, 6, 4), CELL_OCCUPIED, "noise {noise}");
        }
    }

    #[test]
    fn max_range_beam_marks_no_occupied_cell() {
        let mut g = FrontierGrid::new(10.0, 10.0, 1.0).unwrap();
        g.integrate_scan(Pose2::new(1.5, 4.5, 0.0), &scan(0.0, 0.0, 4.0, &[4.0]));
        assert_eq!(count(&g, CELL_OCCUPIED), 0);
        // Cells 1..=5 (x from 1.5 to 5.5) are free.
        for col in 1..=5 {
            assert_eq!(cell(&g, col, 4), CELL_FREE, "col {col}");
        }
        g.integrate_scan(Pose2::new(1.5, 4.5, 0.0), &scan(0.0, 0.0, 4.0, &[100.0]));
        assert_eq!(count(&g, CELL_OCCUPIED), 0);
    }

    #[test]
    fn one_update_per_cell_per_scan_and_hits_win() {
        let mut g = FrontierGrid::new(10.0, 10.0, 1.0).unwrap();
        // 100 beams all along +x through the same cells: one miss update each, not 100.
        let ranges = vec![4.8; 100];
        g.integrate_scan(Pose2::new(1.5, 4.5, 0.0), &scan(0.0, 0.0, 8.0, &ranges));
        let l = g.log_odds()[g.geometry().index(3, 4)];
        assert!((l + 0.405).abs() < 1e-6, "{l}");
        // One short beam ends in cell 3 and the long one passes through it: the hit wins.
        let mut g = FrontierGrid::new(10.0, 10.0, 1.0).unwrap();
        g.integrate_scan(Pose2::new(1.5, 4.5, 0.0), &scan(0.0, 0.0, 8.0, &[1.5, 4.8]));
        assert_eq!(cell(&g, 3, 4), CELL_OCCUPIED);
        assert_eq!(cell(&g, 2, 4), CELL_FREE);
        assert_eq!(cell(&g, 6, 4), CELL_OCCUPIED);
    }

    #[test]
    fn log_odds_are_clamped_so_the_map_recovers() {
        let mut g = FrontierGrid::new(10.0, 10.0, 1.0).unwrap();
        let p = *g.params();
        let hit = scan(0.0, 0.0, 8.0, &[4.8]);
        for _ in 0..100 {
            g.integrate_scan(Pose2::new(1.5, 4.5, 0.0), &hit);
        }
        let idx = g.geometry().index(6, 4);
        assert_eq!(g.log_odds()[idx], p.max);
        // The obstacle goes away: beams now pass through; the cell turns free after a bounded
        // number of scans.
        let pass = scan(0.0, 0.0, 8.0, &[8.0]);
        let mut scans = 0;
        while g.cells()[idx] != CELL_FREE {
            g.integrate_scan(Pose2::new(1.5, 4.5, 0.0), &pass);
            scans += 1;
            assert!(scans < 20);
        }
        assert_eq!(scans, ((p.max + p.threshold) / -p.miss).ceil() as usize);
        for _ in 0..100 {
            g.integrate_scan(Pose2::new(1.5, 4.5, 0.0), &pass);
        }
        assert_eq!(g.log_odds()[idx], p.min);
    }

    #[test]
    fn bad_input_is_ignored() {
        let mut g = FrontierGrid::new(10.0, 10.0, 1.0).unwrap();
        let good = scan(0.0, 0.1, 8.0, &[3.0, 4.0]);
        for pose in [
            Pose2::new(f64::NAN, 1.0, 0.0),
            Pose2::new(1.0, f64::INFINITY, 0.0),
            Pose2::new(-1.0, 1.0, 0.0),
            Pose2::new(1.0, 10.5, 0.0),
        ] {
            g.integrate_scan(pose, &good);
            g.integrate_footprint(pose, 0.5);
            g.mark_occupied(pose.x, pose.y);
        }
        let here = Pose2::new(1.5, 1.5, 0.0);
        g.integrate_scan(Pose2::new(1.5, 1.5, f64::NAN), &good);
        for bad in [
            scan(f64::NAN, 0.1, 8.0, &[3.0]),
            scan(0.0, f64::INFINITY, 8.0, &[3.0]),
            scan(0.0, 0.1, f64::NAN, &[3.0]),
            scan(0.0, 0.1, 0.0, &[3.0]),
            scan(0.0, 0.1, -1.0, &[3.0]),
            scan(0.0, 0.1, 8.0, &[f64::NAN, -1.0, 0.0, f64::NEG_INFINITY]),
        ] {
            g.integrate_scan(here, &bad);
        }
        g.integrate_footprint(here, f64::NAN);
        g.integrate_footprint(here, -1.0);
        g.integrate_footprint(here, f64::INFINITY);
        assert!(g.cells().iter().all(|c| *c == CELL_UNEXPLORED));
        // n_beams above capacity is clamped by Scan::ranges.
        let mut big = scan(0.0, 0.001, 2.0, &[1.0; 4]);
        big.n_beams = u32::MAX;
        g.integrate_scan(here, &big);
        assert!(g.cells().iter().any(|c| *c != CELL_UNEXPLORED));
        assert_eq!(big.ranges().len(), MAX_BEAMS);
    }

    #[test]
    fn footprint_marks_a_disk() {
        let mut g = FrontierGrid::new(10.0, 10.0, 0.1).unwrap();
        let (x, y, r) = (5.0, 5.0, 0.5);
        g.integrate_footprint(Pose2::new(x, y, 0.3), r);
        let geo = *g.geometry();
        let mut free = 0;
        for i in 0..geo.len() {
            let (c, row) = geo.cell_of_index(i);
            let (cx, cy) = geo.cell_center(c, row);
            let inside = (cx - x).hypot(cy - y) <= r;
            let expect = if inside { CELL_FREE } else { CELL_UNEXPLORED };
            assert_eq!(g.cells()[i], expect, "cell {c},{row}");
            free += inside as usize;
        }
        // π r² / res² ≈ 78.5 cells.
        assert!((free as f64 - PI * 25.0).abs() < 6.0, "{free}");
        // A disk smaller than a cell still frees the cell under the robot.
        let mut g = FrontierGrid::new(10.0, 10.0, 1.0).unwrap();
        g.integrate_footprint(Pose2::new(2.1, 3.9, 0.0), 0.2);
        assert_eq!(count(&g, CELL_FREE), 1);
        assert_eq!(cell(&g, 2, 3), CELL_FREE);
        // A disk over the corner of the arena is clipped.
        let mut g = FrontierGrid::new(10.0, 10.0, 1.0).unwrap();
        g.integrate_footprint(Pose2::new(-0.5, -0.5, 0.0), 1.5);
        assert_eq!(count(&g, CELL_FREE), 1);
        assert_eq!(cell(&g, 0, 0), CELL_FREE);
    }

    #[test]
    fn touch_beats_footprint_and_touch_alone_builds_the_map() {
        let mut g = FrontierGrid::new(10.0, 10.0, 1.0).unwrap();
        g.mark_occupied(3.2, 3.7);
        assert_eq!(cell(&g, 3, 3), CELL_OCCUPIED);
        assert_eq!(g.log_odds()[g.geometry().index(3, 3)], g.params().max);
        for _ in 0..1000 {
            g.integrate_footprint(Pose2::new(3.5, 3.5, 0.0), 1.0);
        }
        assert_eq!(cell(&g, 3, 3), CELL_OCCUPIED);
        assert_eq!(cell(&g, 2, 3), CELL_FREE);
        // A free cell touched becomes occupied at once.
        g.mark_occupied(2.5, 3.5);
        assert_eq!(cell(&g, 2, 3), CELL_OCCUPIED);
        g.mark_occupied(f64::NAN, 1.0);
        g.mark_occupied(11.0, 1.0);
    }

    #[test]
    fn write_fills_the_message_but_not_the_header() {
        let mut g = FrontierGrid::new(4.0, 3.0, 0.5).unwrap();
        g.integrate_scan(Pose2::new(0.25, 0.25, 0.0), &scan(0.0, 0.0, 8.0, &[2.1]));
        let mut out: Box<Grid> = bytemuck::zeroed_box();
        out.header.seq = 42;
        out.kind = 7;
        g.write(&mut out);
        assert_eq!(out.header.seq, 42);
        assert_eq!((out.width, out.height, out.kind), (8, 6, GRID_FRONTIER));
        assert_eq!(
            (out.resolution, out.origin_x, out.origin_y),
            (0.5, 0.0, 0.0)
        );
        assert_eq!(out.cells(), g.cells());
        assert_eq!(out.validate(), Ok(()));
        assert_eq!(out.cells[0..6], [1, 1, 1, 1, 1, 2]);
    }

    /// Distances (m) from each wall of the room `[lo, hi]²` along a beam; the nearest is the range.
    fn cast_in_room(x: f64, y: f64, a: f64, lo: f64, hi: f64) -> f64 {
        let (s, c) = a.sin_cos();
        let mut best = f64::INFINITY;
        for (d, p, wall) in [(c, x, lo), (c, x, hi), (s, y, lo), (s, y, hi)] {
            if d.abs() > 1e-12 {
                let t = (wall - p) / d;
                if t > 0.0 {
                    best = best.min(t);
                }
            }
        }
        best
    }

    #[test]
    fn simulated_room_scans_put_occupied_cells_on_the_walls() {
        // Room [1.03, 6.97]² inside an 8 m arena (walls not on cell edges), 0.1 m cells.
        let (lo, hi, res) = (1.03, 6.97, 0.1);
        let mut g = FrontierGrid::new(8.0, 8.0, res).unwrap();
        let n = 720;
        let inc = TAU / n as f64;
        let mut ranges = vec![0.0; n];
        for (k, pose) in [
            Pose2::new(4.0, 4.0, 0.0),
            Pose2::new(2.0, 2.5, 1.0),
            Pose2::new(6.0, 5.5, -2.0),
            Pose2::new(2.5, 6.0, 3.0),
            Pose2::new(5.5, 1.8, -0.5),
        ]
        .into_iter()
        .enumerate()
        {
            for (i, r) in ranges.iter_mut().enumerate() {
                *r = cast_in_room(pose.x, pose.y, pose.theta - PI + i as f64 * inc, lo, hi);
                // A little deterministic range noise.
                *r += 0.01 * ((i * 7 + k * 13) % 5) as f64 - 0.02;
            }
            g.integrate_scan(pose, &scan(-PI, inc, 8.0, &ranges));
        }
        let geo = *g.geometry();
        // Distance from the square outline of the room.
        let dist_to_wall = |x: f64, y: f64| {
            let seg = |d_across: f64, along: f64| {
                let outside = (lo - along).max(along - hi).max(0.0);
                d_across.hypot(outside)
            };
            seg(x - lo, y)
                .min(seg(x - hi, y))
                .min(seg(y - lo, x))
                .min(seg(y - hi, x))
        };
        let mut occupied = 0;
        let mut interior = 0;
        let mut interior_free = 0;
        for i in 0..geo.len() {
            let (c, r) = geo.cell_of_index(i);
            let (x, y) = geo.cell_center(c, r);
            let v = g.cells()[i];
            if v == CELL_OCCUPIED {
                occupied += 1;
                assert!(
                    dist_to_wall(x, y) <= 1.5 * res,
                    "occupied cell at ({x}, {y}) off the walls"
                );
            }
            let deep_inside = x > lo + res && x < hi - res && y > lo + res && y < hi - res;
            if deep_inside {
                interior += 1;
                interior_free += (v == CELL_FREE) as usize;
                assert_ne!(v, CELL_OCCUPIED);
            }
            // Nothing outside the room is seen.
            if x < lo - res || x > hi + res || y < lo - res || y > hi + res {
                assert_eq!(v, CELL_UNEXPLORED, "({x}, {y})");
            }
        }
        // The walls are ~4 × 60 cells long; most of their cells are found.
        assert!(occupied > 200, "{occupied}");
        assert!(
            interior_free as f64 > 0.97 * interior as f64,
            "{interior_free}/{interior}"
        );
    }

    #[derive(Debug, Clone)]
    enum Op {
        Scan(Pose2, f64, f64, f64, Vec<f64>),
        Footprint(Pose2, f64),
        Touch(f64, f64),
    }

    fn any_f64() -> impl Strategy<Value = f64> {
        prop_oneof![
            8 => -2.0..8.0f64,
            1 => Just(f64::NAN),
            1 => Just(f64::INFINITY),
            1 => Just(-1e30),
        ]
    }

    fn op() -> impl Strategy<Value = Op> {
        let pose = || (any_f64(), any_f64(), any_f64()).prop_map(|(x, y, t)| Pose2::new(x, y, t));
        prop_oneof![
            (
                pose(),
                any_f64(),
                any_f64(),
                any_f64(),
                prop::collection::vec(any_f64(), 0..40)
            )
                .prop_map(|(p, a, i, m, r)| Op::Scan(p, a, i, m, r)),
            (pose(), any_f64()).prop_map(|(p, r)| Op::Footprint(p, r)),
            (any_f64(), any_f64()).prop_map(|(x, y)| Op::Touch(x, y)),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Whatever happens, every cell stays in {0, 1, 2}, matches its log-odds, and the
        /// log-odds stay within their bounds.
        #[test]
        fn cells_stay_in_range(ops in prop::collection::vec(op(), 1..30)) {
            let mut g = FrontierGrid::new(6.0, 5.0, 0.25).unwrap();
            let p = *g.params();
            for op in ops {
                match op {
                    Op::Scan(pose, a, i, m, r) => g.integrate_scan(pose, &scan(a, i / 10.0, m, &r)),
                    Op::Footprint(pose, r) => g.integrate_footprint(pose, r),
                    Op::Touch(x, y) => g.mark_occupied(x, y),
                }
                for (c, l) in g.cells().iter().zip(g.log_odds()) {
                    prop_assert!(*c <= CELL_OCCUPIED);
                    prop_assert!(*l >= p.min && *l <= p.max);
                    prop_assert_eq!(*c, p.classify(*l));
                }
                prop_assert!(g.marks.iter().all(|m| *m == MARK_NONE));
            }
            let mut out: Box<Grid> = bytemuck::zeroed_box();
            g.write(&mut out);
            prop_assert_eq!(out.validate(), Ok(()));
        }
    }

    #[test]
    fn params_are_checked() {
        let ok = LogOddsParams::default();
        assert!(ok.check().is_ok());
        for bad in [
            LogOddsParams { hit: -1.0, ..ok },
            LogOddsParams { miss: 0.1, ..ok },
            LogOddsParams {
                threshold: 5.0,
                ..ok
            },
            LogOddsParams { min: 1.0, ..ok },
            LogOddsParams {
                touch: f32::NAN,
                ..ok
            },
            LogOddsParams {
                hit_depth_cells: 2.0,
                ..ok
            },
        ] {
            assert!(
                FrontierGrid::with_params(1.0, 1.0, 0.1, bad).is_err(),
                "{bad:?}"
            );
        }
    }
}
