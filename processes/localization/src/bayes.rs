//! The histogram (grid) Bayes filter (algorithms §6.3): the belief Bel(x) over cells of the arena ×
//! heading bins, predicted by the motion model and corrected by the measurement likelihood,
//! Bel(x_t) = η p(z_t | x_t) Bel̄(x_t).
//!
//! Discretisation (after Thrun, *Probabilistic Robotics*, §4.1): cell (ix, iy) of slice k holds
//! the probability that the robot is in that cell with heading θ_k = k·2π/n_θ. At 100 Hz a step
//! moves the robot ~1 cm, far less than a cell, so rounding every step's shift would freeze the
//! belief. Instead each heading slice k carries a sub-cell offset r_k (and all slices a heading
//! offset φ): the motion is integrated exactly into r_k and φ, and the slice is shifted by whole
//! cells (bins) when they exceed half a cell (bin). The motion noise is a separable 3-tap blur per
//! step whose variance equals the step's (exact for any small variance, unlike a sampled
//! Gaussian kernel). The likelihood is evaluated at cell centres with the measurement σ inflated
//! by the in-cell spread (deviation from the source's exact p(z | x): a cell is not a point).

use crate::models::{BeaconTable, odometry_is_plausible, sinc, wrap_near};
use crate::noise::NoiseModel;
use crate::{Estimator, ReadingError, Readings};
use core::f64::consts::{PI, TAU};
use mole_types::Setting;
use mole_types::{
    BeaconReading, BeaconSite, Beacons, EstimatorKind, Fix, MAX_BEACONS, Odom, Pose2, WorldMap,
    wrap_angle,
};
use serde::{Deserialize, Serialize};

/// Default cell size (m).
pub const DEFAULT_CELL_SIZE: f64 = 0.1;
/// Default number of heading bins.
pub const DEFAULT_HEADING_BINS: usize = 16;
/// Default cap on cells per axis: the belief stays ≤ 200 × 200 × n_θ.
pub const DEFAULT_MAX_CELLS_PER_AXIS: usize = 200;
/// Initial position σ (m) around the start.
pub const INITIAL_STD_XY: f64 = 0.05;
/// Initial heading σ (rad) around the start.
pub const INITIAL_STD_THETA: f64 = 0.05;
/// After each step, probabilities below this become 0 (keeps the support, and the work of
/// the correction, small; the mass dropped is < 10⁻¹² in total).
pub const PRUNE_BELOW: f64 = 1e-18;
/// Largest blur weight a of one [a, 1 − 2a, a] pass (variance 2a cells²).
const MAX_BLUR: f64 = 0.25;

/// Tuning of a [`HistogramFilter`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Setting)]
#[serde(default, deny_unknown_fields)]
pub struct BayesConfig {
    /// Cell size (m); raised so that no axis has more than `max_cells_per_axis` cells.
    #[setting(above = 0.0)]
    pub cell_size: f64,
    /// n_θ, heading bins over the full circle (≥ 1).
    #[setting(min = 1)]
    pub heading_bins: usize,
    /// Cap on cells per axis.
    #[setting(min = 1)]
    pub max_cells_per_axis: usize,
    /// Start from a uniform belief (global localisation) instead of a Gaussian at the start.
    pub uniform_prior: bool,
}

impl Default for BayesConfig {
    fn default() -> Self {
        Self {
            cell_size: DEFAULT_CELL_SIZE,
            heading_bins: DEFAULT_HEADING_BINS,
            max_cells_per_axis: DEFAULT_MAX_CELLS_PER_AXIS,
            uniform_prior: false,
        }
    }
}

/// Per-slice sums of the belief for the summary: Σp, Σp·x, Σp·y, Σp·x², Σp·y², Σp·x·y.
type Moments = [f64; 6];

/// The grid belief Bel(x) over (x, y, θ) and its two buffers (algorithms §6.3).
#[derive(Debug, Clone)]
pub struct HistogramFilter {
    nx: usize,
    ny: usize,
    nt: usize,
    cell: f64,
    bin: f64,
    /// Bel, index (k·ny + iy)·nx + ix.
    bel: Vec<f64>,
    /// The second buffer: Bel̄ during prediction, log-likelihoods during correction.
    scratch: Vec<f64>,
    /// Per-cell log-likelihood of the heading-free terms (ranges, fix).
    lr: Vec<f64>,
    /// Sub-cell offset r_k (m) of each heading slice.
    offset: Vec<[f64; 2]>,
    offset_next: Vec<[f64; 2]>,
    /// Heading offset φ (rad) of every slice, in [−bin/2, bin/2).
    phi: f64,
    /// Per beacon table (slot-major, nx·ny each): distance from the cell centre (m).
    dist: Vec<f32>,
    /// Per beacon table: direction from the cell centre to the beacon (rad).
    angle: Vec<f32>,
    /// Per beacon table: −½ / σ_b,eff² of a bearing from this cell.
    bearing_weight: Vec<f32>,
    /// Table slot of each beacon id.
    slot: [Option<usize>; MAX_BEACONS],
    /// Readings of this correction: (slot, range, bearing).
    pending: [(usize, f64, f64); MAX_BEACONS],
    moments: Vec<Moments>,
    noise: NoiseModel,
    mean: Pose2,
    cov: [f64; 9],
    ignored: u64,
    rejected: u64,
}

/// 3-tap blur weight a for a variance `var` in units of cells², capped at [`MAX_BLUR`].
#[inline]
fn blur_weight(var: f64, cell: f64) -> f64 {
    let a = 0.5 * var / (cell * cell);
    if a.is_finite() {
        a.clamp(0.0, MAX_BLUR)
    } else {
        0.0
    }
}

impl HistogramFilter {
    /// A filter over the arena `[0, width] × [0, height]` at `initial`, with the beacons' and
    /// sensors' noise. Non-finite or non-positive sizes become 1 m; a non-finite start gives a
    /// uniform belief.
    pub fn new(
        width: f64,
        height: f64,
        initial: Pose2,
        config: BayesConfig,
        noise: NoiseModel,
        beacon_sites: &[BeaconSite],
    ) -> Self {
        let size = |v: f64| if v.is_finite() && v > 0.0 { v } else { 1.0 };
        let (width, height) = (size(width), size(height));
        let max_axis = config.max_cells_per_axis.max(1) as f64;
        let mut cell = if config.cell_size.is_finite() && config.cell_size > 0.0 {
            config.cell_size
        } else {
            DEFAULT_CELL_SIZE
        };
        cell = cell.max(width / max_axis).max(height / max_axis);
        let nx = ((width / cell).ceil() as usize).clamp(1, max_axis as usize);
        let ny = ((height / cell).ceil() as usize).clamp(1, max_axis as usize);
        let nt = config.heading_bins.clamp(1, 360);
        let bin = TAU / nt as f64;
        let n_cells = nx * ny;

        let beacons = BeaconTable::new(beacon_sites);
        let mut slot = [None; MAX_BEACONS];
        let mut n_slots = 0;
        for (id, s) in slot.iter_mut().enumerate() {
            if beacons.get(id as u32).is_some() {
                *s = Some(n_slots);
                n_slots += 1;
            }
        }
        let mut dist = vec![0.0f32; n_slots * n_cells];
        let mut angle = vec![0.0f32; n_slots * n_cells];
        let mut bearing_weight = vec![0.0f32; n_slots * n_cells];
        let sb2 = noise.beacon_bearing_std * noise.beacon_bearing_std + bin * bin / 12.0;
        for (id, s) in slot.iter().enumerate() {
            let (Some(s), Some((bx, by))) = (s, beacons.get(id as u32)) else {
                continue;
            };
            for iy in 0..ny {
                for ix in 0..nx {
                    let (cx, cy) = ((ix as f64 + 0.5) * cell, (iy as f64 + 0.5) * cell);
                    let (dx, dy) = (bx - cx, by - cy);
                    let d = dx.hypot(dy);
                    let c = s * n_cells + iy * nx + ix;
                    dist[c] = d as f32;
                    angle[c] = dy.atan2(dx) as f32;
                    // In-cell spread seen from the beacon: ~ (cell/d)²/6 rad²; none within a cell.
                    bearing_weight[c] = if d > cell {
                        (-0.5 / (sb2 + cell * cell / (6.0 * d * d))) as f32
                    } else {
                        0.0
                    };
                }
            }
        }

        let mut f = Self {
            nx,
            ny,
            nt,
            cell,
            bin,
            bel: vec![0.0; n_cells * nt],
            scratch: vec![0.0; n_cells * nt],
            lr: vec![0.0; n_cells],
            offset: vec![[0.0; 2]; nt],
            offset_next: vec![[0.0; 2]; nt],
            phi: 0.0,
            dist,
            angle,
            bearing_weight,
            slot,
            pending: [(0, 0.0, 0.0); MAX_BEACONS],
            moments: vec![[0.0; 6]; nt],
            noise,
            mean: Pose2::default(),
            cov: [0.0; 9],
            ignored: 0,
            rejected: 0,
        };
        let start_ok = initial.x.is_finite()
            && initial.y.is_finite()
            && initial.theta.is_finite()
            && (0.0..=nx as f64 * cell).contains(&initial.x)
            && (0.0..=ny as f64 * cell).contains(&initial.y);
        if config.uniform_prior || !start_ok {
            f.bel.fill(1.0 / (n_cells * nt) as f64);
        } else {
            f.init_gaussian(initial);
        }
        f.finish();
        f
    }

    /// The filter for the world in `map` with `config`.
    pub fn from_map_with(map: &WorldMap, config: BayesConfig) -> Self {
        Self::new(
            map.arena_width,
            map.arena_height,
            Pose2::new(map.start_x, map.start_y, map.start_theta),
            config,
            NoiseModel::from_map(map),
            map.beacons(),
        )
    }

    /// The filter for the world in `map` with the default [`BayesConfig`].
    pub fn from_map(map: &WorldMap) -> Self {
        Self::from_map_with(map, BayesConfig::default())
    }

    /// Grid size (n_x, n_y, n_θ).
    pub fn dims(&self) -> (usize, usize, usize) {
        (self.nx, self.ny, self.nt)
    }

    /// Cell size (m).
    pub fn cell_size(&self) -> f64 {
        self.cell
    }

    /// The belief, index (k·n_y + iy)·n_x + ix.
    pub fn belief(&self) -> &[f64] {
        &self.bel
    }

    /// The noise the likelihood tables were built with.
    pub fn noise(&self) -> &NoiseModel {
        &self.noise
    }

    /// The most probable (ix, iy, k).
    pub fn argmax(&self) -> (usize, usize, usize) {
        let mut best = (0, f64::NEG_INFINITY);
        for (i, &p) in self.bel.iter().enumerate() {
            if p > best.1 {
                best = (i, p);
            }
        }
        let i = best.0;
        (
            i % self.nx,
            (i / self.nx) % self.ny,
            i / (self.nx * self.ny),
        )
    }

    /// The cell (ix, iy) containing the point (x, y), if inside the grid.
    pub fn cell_of(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let (fx, fy) = (x / self.cell, y / self.cell);
        if !(fx >= 0.0 && fy >= 0.0 && fx < self.nx as f64 && fy < self.ny as f64) {
            return None;
        }
        Some((fx as usize, fy as usize))
    }

    /// A Gaussian around `initial` sampled at the cell centres and bin centres; the start cell
    /// and bin always carry the peak.
    fn init_gaussian(&mut self, initial: Pose2) {
        let (ix0, iy0) = self.cell_of(initial.x, initial.y).unwrap_or((0, 0));
        let k0 = (wrap_angle(initial.theta) / self.bin).round() as isize;
        let k0 = k0.rem_euclid(self.nt as isize) as usize;
        let centre = |i: usize| (i as f64 + 0.5) * self.cell;
        let r = [initial.x - centre(ix0), initial.y - centre(iy0)];
        self.offset.fill(r);
        self.phi = wrap_angle(initial.theta - k0 as f64 * self.bin);
        let (s_xy, s_th) = (INITIAL_STD_XY, INITIAL_STD_THETA);
        let (nx, ny) = (self.nx, self.ny);
        for k in 0..self.nt {
            let dk = wrap_angle((k as f64 - k0 as f64) * self.bin);
            let pk = (-0.5 * dk * dk / (s_th * s_th)).exp();
            for iy in 0..ny {
                let dy = (iy as f64 - iy0 as f64) * self.cell;
                for ix in 0..nx {
                    let dx = (ix as f64 - ix0 as f64) * self.cell;
                    self.bel[(k * ny + iy) * nx + ix] =
                        pk * (-0.5 * (dx * dx + dy * dy) / (s_xy * s_xy)).exp();
                }
            }
        }
    }

    /// Prediction (algorithms §6.3), Bel̄(x_t) = Σ p(x_t | x_{t−1}, u_t) Bel(x_{t−1}): each slice moves
    /// by the unicycle chord of its own heading (Thrun §5.3), then the motion noise blurs x, y
    /// (per slice, σ_v² along the heading) and θ (σ_ω²), and η renormalises (mass pushed off the
    /// arena is dropped).
    ///
    /// Odometry that is not plausible ([`odometry_is_plausible`]) is ignored and counted.
    pub fn predict_with(&mut self, v: f64, omega: f64, dt: f64) -> Result<(), ReadingError> {
        if !odometry_is_plausible(v, omega, dt) {
            self.ignored += 1;
            return Err(ReadingError::Invalid);
        }
        if dt == 0.0 {
            return Ok(());
        }
        let (nx, ny, nt, n_cells) = (self.nx, self.ny, self.nt, self.nx * self.ny);
        let half = 0.5 * omega * dt;
        let s = v * dt * sinc(half);
        let floor = self.noise.r_floor(dt);
        let var_along = (self.noise.odom_v_std * dt).powi(2) + floor[(0, 0)];
        let var_across = (s * self.noise.odom_omega_std * dt * 0.5).powi(2) + floor[(1, 1)];
        // Pass 1: shift each slice by whole cells and blur along x (bel → scratch).
        for k in 0..nt {
            let heading = k as f64 * self.bin + self.phi;
            let (sin_h, cos_h) = (heading + half).sin_cos();
            let o = &mut self.offset[k];
            o[0] += s * cos_h;
            o[1] += s * sin_h;
            let shift_x = (o[0] / self.cell).round();
            let shift_y = (o[1] / self.cell).round();
            o[0] -= shift_x * self.cell;
            o[1] -= shift_y * self.cell;
            let (sx, sy) = (
                shift_x.clamp(-(nx as f64), nx as f64) as isize,
                shift_y.clamp(-(ny as f64), ny as f64) as isize,
            );
            let (c2, s2) = (cos_h * cos_h, sin_h * sin_h);
            let ax = blur_weight(var_along * c2 + var_across * s2, self.cell);
            let ay = blur_weight(var_along * s2 + var_across * c2, self.cell);
            let base = k * n_cells;
            for iy in 0..ny {
                let dst = &mut self.scratch[base + iy * nx..base + (iy + 1) * nx];
                let src_y = iy as isize - sy;
                if src_y < 0 || src_y >= ny as isize {
                    dst.fill(0.0);
                    continue;
                }
                let src = &self.bel[base + src_y as usize * nx..base + (src_y as usize + 1) * nx];
                let at = |i: isize| -> f64 {
                    if i >= 0 && (i as usize) < nx {
                        src[i as usize]
                    } else {
                        0.0
                    }
                };
                let centre = 1.0 - 2.0 * ax;
                for (ix, d) in dst.iter_mut().enumerate() {
                    let i = ix as isize - sx;
                    *d = ax * (at(i - 1) + at(i + 1)) + centre * at(i);
                }
            }
            // Pass 2: blur along y (scratch → bel), rows as vectors.
            let centre = 1.0 - 2.0 * ay;
            for iy in 0..ny {
                let row = base + iy * nx;
                for ix in 0..nx {
                    let up = if iy + 1 < ny {
                        self.scratch[row + nx + ix]
                    } else {
                        0.0
                    };
                    let down = if iy > 0 {
                        self.scratch[row - nx + ix]
                    } else {
                        0.0
                    };
                    self.bel[row + ix] = ay * (up + down) + centre * self.scratch[row + ix];
                }
            }
        }
        // Pass 3: rotate slices by whole bins and blur along θ, cyclic (bel → scratch).
        self.phi += omega * dt;
        let turns = (self.phi / self.bin).round();
        self.phi -= turns * self.bin;
        let rot = (turns.clamp(-1e9, 1e9) as i64).rem_euclid(nt as i64) as usize;
        let var_theta = (self.noise.odom_omega_std * dt).powi(2) + floor[(2, 2)];
        let at = blur_weight(var_theta, self.bin);
        let centre = 1.0 - 2.0 * at;
        for k in 0..nt {
            let src = (k + nt - rot) % nt;
            let (prev, next) = ((src + nt - 1) % nt, (src + 1) % nt);
            self.offset_next[k] = self.offset[src];
            let (dst, bel) = (&mut self.scratch[k * n_cells..(k + 1) * n_cells], &self.bel);
            if nt == 1 {
                dst.copy_from_slice(&bel[..n_cells]);
                continue;
            }
            let (p, c, n) = (
                &bel[prev * n_cells..(prev + 1) * n_cells],
                &bel[src * n_cells..(src + 1) * n_cells],
                &bel[next * n_cells..(next + 1) * n_cells],
            );
            for i in 0..n_cells {
                dst[i] = at * (p[i] + n[i]) + centre * c[i];
            }
        }
        core::mem::swap(&mut self.bel, &mut self.scratch);
        core::mem::swap(&mut self.offset, &mut self.offset_next);
        self.finish();
        Ok(())
    }

    /// Queues one beacon reading for the next [`HistogramFilter::apply_correction`].
    fn queue_beacon(&mut self, n: usize, r: &BeaconReading) -> Result<(), ReadingError> {
        if !(r.range.is_finite() && r.bearing.is_finite() && r.range >= 0.0) {
            return Err(ReadingError::Invalid);
        }
        let Some(slot) = self.slot.get(r.id as usize).copied().flatten() else {
            return Err(ReadingError::UnknownBeacon(r.id));
        };
        self.pending[n] = (slot, r.range, wrap_angle(r.bearing));
        Ok(())
    }

    /// Correction (algorithms §6.3), Bel(x_t) = η p(z_t | x_t) Bel̄(x_t), with the beacon readings
    /// (range and bearing, bearing error wrapped) and the fix as independent Gaussians; σ are
    /// inflated by the in-cell spread (cell²/6 on ranges and positions, bin²/12 and
    /// (cell/d)²/6 on bearings); `None` for a sensor without a reading this step. Returns how
    /// many readings were used.
    pub fn apply_correction(&mut self, beacons: Option<&Beacons>, fix: Option<&Fix>) -> usize {
        let mut n = 0;
        if let Some(beacons) = beacons {
            if beacons.n_readings as usize > beacons.readings.len() {
                self.ignored += 1;
            }
            for r in beacons.readings() {
                match self.queue_beacon(n, r) {
                    Ok(()) => n += 1,
                    Err(_) => self.ignored += 1,
                }
            }
        }
        let fix = match fix {
            None => None,
            Some(fix) if fix.valid == 0 => None,
            Some(fix) if fix.valid == 1 && fix.x.is_finite() && fix.y.is_finite() => Some(fix),
            Some(_) => {
                self.ignored += 1;
                None
            }
        };
        if n == 0 && fix.is_none() {
            return 0;
        }
        let (nx, ny, n_cells) = (self.nx, self.ny, self.nx * self.ny);
        let spread = self.cell * self.cell / 6.0;
        // Heading-free terms per cell: ranges and the fix.
        self.lr.fill(0.0);
        let kr = -0.5 / (self.noise.beacon_range_std * self.noise.beacon_range_std + spread);
        for &(slot, range, _) in &self.pending[..n] {
            let dist = &self.dist[slot * n_cells..(slot + 1) * n_cells];
            for (l, &d) in self.lr.iter_mut().zip(dist) {
                let e = range - f64::from(d);
                *l += kr * e * e;
            }
        }
        if let Some(fix) = fix {
            let kf = -0.5 / (self.noise.q_fix(fix.std)[(0, 0)] + spread);
            for iy in 0..ny {
                let ey = fix.y - (iy as f64 + 0.5) * self.cell;
                for ix in 0..nx {
                    let ex = fix.x - (ix as f64 + 0.5) * self.cell;
                    self.lr[iy * nx + ix] += kf * (ex * ex + ey * ey);
                }
            }
        }
        // ln p(z | x) per (cell, slice) where Bel̄ > 0, into scratch; its maximum.
        let mut max = f64::NEG_INFINITY;
        for k in 0..self.nt {
            let h = k as f64 * self.bin + self.phi;
            let base = k * n_cells;
            for c in 0..n_cells {
                if self.bel[base + c] == 0.0 {
                    continue;
                }
                let mut l = self.lr[c];
                for &(slot, _, bearing) in &self.pending[..n] {
                    let t = slot * n_cells + c;
                    let e = wrap_near(bearing - f64::from(self.angle[t]) + h);
                    l += f64::from(self.bearing_weight[t]) * e * e;
                }
                self.scratch[base + c] = l;
                if l > max {
                    max = l;
                }
            }
        }
        if !max.is_finite() {
            self.rejected += 1;
            return 0;
        }
        for (b, &l) in self.bel.iter_mut().zip(self.scratch.iter()) {
            if *b != 0.0 {
                *b *= (l - max).exp();
            }
        }
        self.finish();
        n + usize::from(fix.is_some())
    }

    /// η: normalises the belief (a belief with no mass left becomes uniform), prunes, and
    /// recomputes the mean and covariance.
    fn finish(&mut self) {
        let n_cells = self.nx * self.ny;
        let mut total = 0.0;
        for k in 0..self.nt {
            let mut m = [0.0; 6];
            let slice = &self.bel[k * n_cells..(k + 1) * n_cells];
            for iy in 0..self.ny {
                let y = (iy as f64 + 0.5) * self.cell;
                let row = &slice[iy * self.nx..(iy + 1) * self.nx];
                let (mut p, mut px, mut pxx) = (0.0, 0.0, 0.0);
                for (ix, &b) in row.iter().enumerate() {
                    let x = (ix as f64 + 0.5) * self.cell;
                    p += b;
                    px += b * x;
                    pxx += b * x * x;
                }
                m[0] += p;
                m[1] += px;
                m[2] += p * y;
                m[3] += pxx;
                m[4] += p * y * y;
                m[5] += px * y;
            }
            total += m[0];
            self.moments[k] = m;
        }
        if !(total.is_finite() && total > 0.0) {
            let u = 1.0 / self.bel.len() as f64;
            self.bel.fill(u);
            self.rejected += 1;
            return self.finish_uniform();
        }
        let eta = 1.0 / total;
        for b in self.bel.iter_mut() {
            let p = *b * eta;
            *b = if p < PRUNE_BELOW { 0.0 } else { p };
        }
        for m in self.moments.iter_mut() {
            for v in m.iter_mut() {
                *v *= eta;
            }
        }
        self.summarise();
    }

    /// Moments of a uniform belief, after a reset.
    fn finish_uniform(&mut self) {
        let (w, h) = (self.nx as f64 * self.cell, self.ny as f64 * self.cell);
        for m in self.moments.iter_mut() {
            let p = 1.0 / self.nt as f64;
            // Sums over cell centres of a uniform grid.
            let (ex, ey) = (0.5 * w, 0.5 * h);
            let exx = (w * w - self.cell * self.cell) / 12.0 + ex * ex;
            let eyy = (h * h - self.cell * self.cell) / 12.0 + ey * ey;
            *m = [p, p * ex, p * ey, p * exx, p * eyy, p * ex * ey];
        }
        self.summarise();
    }

    /// Mean (circular mean of θ) and covariance from the per-slice moments, each slice's mass at
    /// its cell centres + r_k and heading θ_k + φ; the in-cell spread cell²/12 (bin²/12) is added.
    fn summarise(&mut self) {
        let (mut m0, mut mx, mut my, mut sc, mut ss) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (k, m) in self.moments.iter().enumerate() {
            let [ox, oy] = self.offset[k];
            let h = k as f64 * self.bin + self.phi;
            m0 += m[0];
            mx += m[1] + ox * m[0];
            my += m[2] + oy * m[0];
            sc += m[0] * h.cos();
            ss += m[0] * h.sin();
        }
        if m0 <= 0.0 {
            return;
        }
        let (ux, uy) = (mx / m0, my / m0);
        let ut = if sc == 0.0 && ss == 0.0 {
            0.0
        } else {
            ss.atan2(sc)
        };
        let (mut cxx, mut cyy, mut cxy, mut cxt, mut cyt, mut ctt) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for (k, m) in self.moments.iter().enumerate() {
            let [ox, oy] = self.offset[k];
            let e = wrap_angle(k as f64 * self.bin + self.phi - ut);
            // Σ p (x + ox − ux)² = Sxx + 2(ox − ux)Sx + (ox − ux)² m.
            let (dx, dy) = (ox - ux, oy - uy);
            cxx += m[3] + 2.0 * dx * m[1] + dx * dx * m[0];
            cyy += m[4] + 2.0 * dy * m[2] + dy * dy * m[0];
            cxy += m[5] + dx * m[2] + dy * m[1] + dx * dy * m[0];
            cxt += e * (m[1] + dx * m[0]);
            cyt += e * (m[2] + dy * m[0]);
            ctt += e * e * m[0];
        }
        let (cell2, bin2) = (self.cell * self.cell / 12.0, self.bin * self.bin / 12.0);
        let (cxx, cyy) = ((cxx / m0).max(0.0) + cell2, (cyy / m0).max(0.0) + cell2);
        let (cxy, cxt, cyt) = (cxy / m0, cxt / m0, cyt / m0);
        let ctt = (ctt / m0).min(PI * PI) + bin2;
        self.mean = Pose2::new(ux, uy, wrap_angle(ut));
        self.cov = [cxx, cxy, cxt, cxy, cyy, cyt, cxt, cyt, ctt];
    }
}

impl Estimator for HistogramFilter {
    fn id(&self) -> u32 {
        EstimatorKind::Bayes.code()
    }

    fn predict(&mut self, odom: &Odom) {
        // Refusals are counted inside.
        let _ = self.predict_with(odom.v, odom.omega, odom.dt);
    }

    fn correct(&mut self, readings: &Readings<'_>) {
        self.apply_correction(readings.beacons, readings.fix);
    }

    fn pose(&self) -> Pose2 {
        self.mean
    }

    fn covariance(&self) -> [f64; 9] {
        self.cov
    }

    fn rejected(&self) -> u64 {
        self.rejected
    }

    fn ignored(&self) -> u64 {
        self.ignored
    }
}

#[cfg(test)]
mod tests;
