//! Beacon placement: beacons stand on reachable cells next to a blocked one (near a wall, where
//! a beacon is mounted), chosen greedily for coverage (the maximum-coverage greedy rule, within
//! `1 − 1/e` of the best placement, Nemhauser, Wolsey and Fisher 1978): each next beacon is the
//! one that brings the most sample points of the reachable space into sight (within the beacon
//! range, no square across the line, as the sensing process sees them), a point counting twice
//! while no beacon sees it and once while one does; ties go to the beacon farthest from those
//! placed, then to a random draw.

use super::ChaCha8Rng;
use crate::free_space::{BLOCKED, FreeSpace, REACHABLE};
use crate::scenario::Scenario;
use mole_types::BeaconSite;
use rand::RngExt;

/// Spacing of the sample points (m).
const SAMPLE_SPACING: f64 = 0.5;
/// Spacing of the candidate sites (m): one per block of this side.
const SITE_SPACING: f64 = 1.0;

/// Up to `count` beacons for the scenario, whose free space is `space`.
pub(super) fn place(
    s: &Scenario,
    space: &FreeSpace,
    count: usize,
    rng: &mut ChaCha8Rng,
) -> Vec<BeaconSite> {
    let (w, h, res) = (space.width, space.height, space.resolution);
    if count == 0 || w == 0 || h == 0 {
        return Vec::new();
    }
    let centre = |k: usize| (((k % w) as f64 + 0.5) * res, ((k / w) as f64 + 0.5) * res);
    // Cells a square overlaps: a line of sight through one is taken as blocked.
    let mut opaque = vec![false; w * h];
    let cell = |v: f64, n: usize| ((v / res).floor().max(0.0) as usize).min(n - 1);
    for o in &s.obstacles {
        let (lo, hi) = (o.min(), o.max());
        if hi.0 < 0.0 || hi.1 < 0.0 || lo.0 > w as f64 * res || lo.1 > h as f64 * res {
            continue;
        }
        for j in cell(lo.1, h)..=cell(hi.1, h) {
            for i in cell(lo.0, w)..=cell(hi.0, w) {
                opaque[j * w + i] = true;
            }
        }
    }
    let sight = |a: (f64, f64), b: (f64, f64)| {
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let steps = ((dx * dx + dy * dy).sqrt() / res).ceil() as usize;
        (1..steps).all(|n| {
            let t = n as f64 / steps as f64;
            let (x, y) = (a.0 + t * dx, a.1 + t * dy);
            !opaque[cell(y, h) * w + cell(x, w)]
        })
    };
    let step = ((SAMPLE_SPACING / res).round() as usize).max(1);
    let block = ((SITE_SPACING / res).round() as usize).max(1);
    let samples: Vec<(f64, f64)> = (0..w * h)
        .filter(|&k| {
            space.cells[k] == REACHABLE && (k % w) % step == step / 2 && (k / w) % step == step / 2
        })
        .map(centre)
        .collect();
    // The first site near a wall in each block of the site spacing.
    let blocked = |i: usize, j: usize| space.cells[j * w + i] == BLOCKED;
    let mut taken = std::collections::HashSet::new();
    let candidates: Vec<(f64, f64)> = (0..w * h)
        .filter(|&k| {
            let (i, j) = (k % w, k / w);
            space.cells[k] == REACHABLE
                && ((i > 0 && blocked(i - 1, j))
                    || (i + 1 < w && blocked(i + 1, j))
                    || (j > 0 && blocked(i, j - 1))
                    || (j + 1 < h && blocked(i, j + 1)))
                && taken.insert((i / block, j / block))
        })
        .map(centre)
        .collect();
    let range = s.sensors.beacon_range_max;
    let d2 = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0) * (a.0 - b.0) + (a.1 - b.1) * (a.1 - b.1);
    let visible: Vec<Vec<usize>> = candidates
        .iter()
        .map(|&c| {
            (0..samples.len())
                .filter(|&p| d2(c, samples[p]) <= range * range && sight(c, samples[p]))
                .collect()
        })
        .collect();
    let keys: Vec<u64> = candidates.iter().map(|_| rng.random()).collect();
    let mut seen = vec![0u8; samples.len()];
    let mut nearest = vec![f64::INFINITY; candidates.len()];
    let mut chosen: Vec<usize> = Vec::new();
    while chosen.len() < count.min(candidates.len()) {
        let gain = |c: usize| -> usize {
            visible[c]
                .iter()
                .map(|&p| match seen[p] {
                    0 => 2,
                    1 => 1,
                    _ => 0,
                })
                .sum()
        };
        let rank: Vec<(usize, f64, u64)> = (0..candidates.len())
            .map(|c| (gain(c), nearest[c], keys[c]))
            .collect();
        let best = (0..candidates.len())
            .filter(|c| !chosen.contains(c))
            .max_by(|&a, &b| {
                let (ra, rb) = (rank[a], rank[b]);
                ra.0.cmp(&rb.0)
                    .then(ra.1.total_cmp(&rb.1))
                    .then(ra.2.cmp(&rb.2))
            });
        let Some(best) = best else { break };
        for &p in &visible[best] {
            seen[p] = seen[p].saturating_add(1);
        }
        for (n, &c) in nearest.iter_mut().zip(&candidates) {
            *n = n.min(d2(c, candidates[best]));
        }
        chosen.push(best);
    }
    chosen
        .into_iter()
        .enumerate()
        .map(|(id, c)| BeaconSite {
            x: candidates[c].0,
            y: candidates[c].1,
            id: id as u32,
            _pad: 0,
        })
        .collect()
}
