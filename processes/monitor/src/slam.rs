//! SLAM scoring: a SLAM estimator's landmark map (`localization/landmarks`) against the true
//! beacons of `world/map`, for summary.json's `slam` section and the ellipses of map.png.
//!
//! Each estimated landmark is matched to a true beacon: by its beacon id when it carries one,
//! otherwise (a landmark founded on anonymous readings) to the nearest beacon. A landmark matched
//! to a beacon that another landmark already claimed is an association error (a duplicate or a
//! wrong data association), and so is a landmark naming a beacon the world does not have.

use mole_types::{BeaconSite, LANDMARK_ANONYMOUS, Landmark, Landmarks, MAX_BEACONS, MAX_LANDMARKS};
use serde::{Deserialize, Serialize};
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// χ²₂ 0.95 quantile, −2 ln 0.05: the squared Mahalanobis radius of a 2-D 95% ellipse.
pub const CHI2_2_95: f64 = 5.991_464_547_107_979;

/// summary.json's `slam` section: the estimator's last landmark map against the true beacons.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SlamSummary {
    /// Tick of the landmark map scored (`null`: no map arrived).
    pub tick: Option<u64>,
    /// Landmarks in that map.
    pub landmarks: u32,
    /// Beacons in the world.
    pub true_beacons: u32,
    /// Distinct true beacons some landmark was matched to.
    pub beacons_mapped: u32,
    /// Landmarks founded on anonymous readings (matched to their nearest beacon).
    pub anonymous_landmarks: u32,
    /// Landmarks matched to a beacon another landmark already claimed, plus landmarks naming a
    /// beacon the world does not have.
    pub association_errors: u32,
    /// √(mean squared distance) from each matched landmark to its beacon (`null`: none).
    pub landmark_rmse_m: Option<f64>,
    /// Mean 2-D NEES eᵀΣ⁻¹e of the matched landmarks (2 for a consistent map; `null`: none with
    /// a positive definite Σ).
    pub landmark_nees: Option<f64>,
    /// The 95% interval of that mean for a consistent map, [2·χ²_ν(0.025)/ν, 2·χ²_ν(0.975)/ν]
    /// with ν = `landmark_nees_dof` ([χ²₂ₙ(0.025)/n, χ²₂ₙ(0.975)/n] for independent landmarks).
    pub landmark_nees_interval: Option<[f64; 2]>,
    /// ν: the degrees of freedom of that mean under the estimator's joint covariance, which
    /// it publishes (`Landmarks::nees_dof`: the landmarks share the error of the poses they
    /// were seen from), at most 2n; 2n, as for independent landmarks, when it does not say.
    #[serde(default)]
    pub landmark_nees_dof: Option<f64>,
    /// Landmarks whose NEES was computed (Σ positive definite).
    pub landmark_nees_samples: u32,
    /// `association_errors` over `landmarks` (`null`: no landmark).
    #[serde(default)]
    pub association_error_rate: Option<f64>,
    /// Tick of the newest smoothed trajectory (`localization/trajectory`, GraphSLAM) scored
    /// below (`null`: none arrived, as for every other estimator).
    #[serde(default)]
    pub smoothed_tick: Option<u64>,
    /// Ticks of that trajectory scored: those with the truth and the filter's pose known.
    #[serde(default)]
    pub smoothed_samples: u32,
    /// √(mean squared position error) of the smoothed poses at those ticks.
    #[serde(default)]
    pub smoothed_rmse_m: Option<f64>,
    /// The same for the filter's published poses (`localization/pose`) at the same ticks.
    #[serde(default)]
    pub filter_rmse_same_ticks_m: Option<f64>,
    /// The smoothed poses' RMSE after the rotation and translation that bring them closest to
    /// the truth (the absolute trajectory error): their shape, without the frame error that no
    /// reading after the start can observe.
    #[serde(default)]
    pub smoothed_ate_m: Option<f64>,
    /// The same for the filter's poses at the same ticks, aligned on their own.
    #[serde(default)]
    pub filter_ate_same_ticks_m: Option<f64>,
}

/// The last landmark map received, kept in storage sized once.
#[derive(Debug, Clone)]
pub(crate) struct LandmarkMap {
    landmarks: Vec<Landmark>,
    tick: Option<u64>,
    /// The map's `nees_dof` (0: not given).
    nees_dof: f64,
}

impl LandmarkMap {
    /// Empty, with room for [`MAX_LANDMARKS`].
    pub fn new() -> LandmarkMap {
        LandmarkMap {
            landmarks: Vec::with_capacity(MAX_LANDMARKS),
            tick: None,
            nees_dof: 0.0,
        }
    }

    /// Keeps the latest map (no allocation).
    pub fn on_landmarks(&mut self, map: &Landmarks) {
        self.landmarks.clear();
        self.landmarks.extend_from_slice(map.landmarks());
        self.tick = Some(map.header.tick);
        self.nees_dof = map.nees_dof;
    }

    /// Whether any map arrived.
    pub fn received(&self) -> bool {
        self.tick.is_some()
    }

    /// The landmarks of the latest map.
    pub fn landmarks(&self) -> &[Landmark] {
        &self.landmarks
    }

    /// Scores the latest map against the true beacons (see the module documentation).
    pub fn score(&self, beacons: &[BeaconSite]) -> SlamSummary {
        let beacons = &beacons[..beacons.len().min(MAX_BEACONS)];
        let mut claimed = [false; MAX_BEACONS];
        let mut out = SlamSummary {
            tick: self.tick,
            landmarks: self.landmarks.len() as u32,
            true_beacons: beacons.len() as u32,
            ..SlamSummary::default()
        };
        let (mut squared_sum, mut matched, mut nees_sum) = (0.0, 0u32, 0.0);
        for l in &self.landmarks {
            let anonymous = l.id == LANDMARK_ANONYMOUS;
            out.anonymous_landmarks += u32::from(anonymous);
            let beacon = if anonymous {
                nearest_beacon(beacons, l.x, l.y)
            } else {
                usize::try_from(l.id).ok().filter(|&i| i < beacons.len())
            };
            let Some(i) = beacon else {
                out.association_errors += 1;
                continue;
            };
            if claimed[i] {
                out.association_errors += 1;
            } else {
                claimed[i] = true;
                out.beacons_mapped += 1;
            }
            let e = [l.x - beacons[i].x, l.y - beacons[i].y];
            squared_sum += e[0] * e[0] + e[1] * e[1];
            matched += 1;
            if let Some(nees) = nees_2d(&e, &l.covariance) {
                nees_sum += nees;
                out.landmark_nees_samples += 1;
            }
        }
        let finite = |v: f64| v.is_finite().then_some(v);
        out.landmark_rmse_m = (matched > 0)
            .then(|| (squared_sum / f64::from(matched)).sqrt())
            .and_then(finite);
        out.association_error_rate = (out.landmarks > 0)
            .then(|| f64::from(out.association_errors) / f64::from(out.landmarks));
        let n = out.landmark_nees_samples;
        out.landmark_nees = (n > 0).then(|| nees_sum / f64::from(n)).and_then(finite);
        // The estimator's ν is of all its landmarks; the mean here may be of fewer.
        let independent = 2.0 * f64::from(n);
        let dof = match self.nees_dof {
            d if d > 0.0 => d.clamp(2.0_f64.min(independent), independent),
            _ => independent,
        };
        if n > 0 {
            out.landmark_nees_dof = Some(dof);
            out.landmark_nees_interval = mean_nees_interval_of_dof(dof);
        }
        out
    }
}

/// Index of the beacon nearest to (x, y); `None` without beacons or for a non-finite point.
fn nearest_beacon(beacons: &[BeaconSite], x: f64, y: f64) -> Option<usize> {
    beacons
        .iter()
        .map(|b| (b.x - x).hypot(b.y - y))
        .enumerate()
        .filter(|(_, d)| d.is_finite())
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(i, _)| i)
}

/// eᵀΣ⁻¹e for a 2-D error and a row-major 2×2 Σ (its symmetric part); `None` unless Σ is
/// positive definite.
pub fn nees_2d(e: &[f64; 2], cov: &[f64; 4]) -> Option<f64> {
    let (a, b, d) = (cov[0], 0.5 * (cov[1] + cov[2]), cov[3]);
    let det = a * d - b * b;
    if !(a > 0.0 && det > 0.0) {
        return None;
    }
    let v = (d * e[0] * e[0] - 2.0 * b * e[0] * e[1] + a * e[1] * e[1]) / det;
    v.is_finite().then_some(v)
}

/// The two-sided 95% interval of the mean of n independent χ²_dof NEES values, as Bar-Shalom,
/// Li & Kirubarajan (§5.4) test consistency: n·mean ~ χ²_{n·dof}. `None` for n = 0.
pub fn mean_nees_interval(dof: u32, n: u32) -> Option<[f64; 2]> {
    let total = f64::from(dof) * f64::from(n);
    let chi2 = ChiSquared::new(total).ok()?;
    let n = f64::from(n);
    Some([chi2.inverse_cdf(0.025) / n, chi2.inverse_cdf(0.975) / n])
}

/// The two-sided 95% interval of a mean 2-D NEES whose sum is Satterthwaite's a·χ²_ν (a = 2n/ν,
/// so the mean is 2·χ²_ν/ν): [2·χ²_ν(0.025)/ν, 2·χ²_ν(0.975)/ν]. ν = 2n gives
/// [`mean_nees_interval`]`(2, n)`. `None` unless ν > 0.
pub fn mean_nees_interval_of_dof(dof: f64) -> Option<[f64; 2]> {
    let chi2 = ChiSquared::new(dof).ok()?;
    Some([
        2.0 * chi2.inverse_cdf(0.025) / dof,
        2.0 * chi2.inverse_cdf(0.975) / dof,
    ])
}

/// A 95% confidence ellipse: semi-axes (m) and the major axis's angle from +x (rad).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Ellipse {
    pub major: f64,
    pub minor: f64,
    pub angle: f64,
}

/// The 95% ellipse of a row-major 2×2 covariance (its symmetric part): semi-axes √(χ²₂ 0.95 · λ)
/// along the eigenvectors. `None` when Σ has a negative eigenvalue or a non-finite entry.
pub(crate) fn confidence_ellipse(cov: &[f64; 4]) -> Option<Ellipse> {
    let (a, b, d) = (cov[0], 0.5 * (cov[1] + cov[2]), cov[3]);
    let mean = 0.5 * (a + d);
    let radius = (0.5 * (a - d)).hypot(b);
    let (large, small) = (mean + radius, mean - radius);
    // A positive semi-definite Σ may round to a tiny negative minor eigenvalue.
    if !(large.is_finite() && small >= -1e-12 * large) {
        return None;
    }
    let small = small.max(0.0);
    Some(Ellipse {
        major: (CHI2_2_95 * large).sqrt(),
        minor: (CHI2_2_95 * small).sqrt(),
        angle: 0.5 * (2.0 * b).atan2(a - d),
    })
}
