//! The particle filter's set size over a run, from `localization/particles`' `n_filter`: with
//! KLD-sampling it shrinks as the belief tightens and grows when the robot is lost.

use serde::{Deserialize, Serialize};

/// Most `[tick, particles]` points kept; past it every second point is dropped and only every
/// second change is kept from then on, so a run of any length fits in preallocated room.
pub const MAX_COUNT_POINTS: usize = 2048;

/// summary.json's `particles`: the set size over the run.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ParticleSummary {
    pub min: u32,
    pub max: u32,
    /// Mean over the particle messages (published every few steps).
    pub mean: f64,
    /// The size in the last message.
    pub last: u32,
    /// `[tick, particles]` at the first message and at each change (thinned past
    /// [`MAX_COUNT_POINTS`]).
    pub series: Vec<[u64; 2]>,
}

/// What the monitor keeps of the particle counts.
#[derive(Debug, Clone)]
pub struct ParticleCounts {
    min: u32,
    max: u32,
    sum: f64,
    messages: u64,
    last: Option<u32>,
    series: Vec<[u64; 2]>,
    /// Changes seen since the last kept point; every `stride`-th one is kept.
    changes: u64,
    stride: u64,
}

impl Default for ParticleCounts {
    fn default() -> Self {
        Self {
            min: u32::MAX,
            max: 0,
            sum: 0.0,
            messages: 0,
            last: None,
            series: Vec::with_capacity(MAX_COUNT_POINTS),
            changes: 0,
            stride: 1,
        }
    }
}

impl ParticleCounts {
    /// One particle message: the filter held `n` particles at `tick`.
    pub fn record(&mut self, tick: u64, n: u32) {
        (self.min, self.max) = (self.min.min(n), self.max.max(n));
        self.sum += f64::from(n);
        self.messages += 1;
        let changed = self.last != Some(n);
        self.last = Some(n);
        if !changed {
            return;
        }
        self.changes += 1;
        if self.series.is_empty() || self.changes >= self.stride {
            self.changes = 0;
            if self.series.len() == MAX_COUNT_POINTS {
                // Keep the first point and every second one after it.
                let mut keep = 0;
                for i in (0..MAX_COUNT_POINTS).step_by(2) {
                    self.series[keep] = self.series[i];
                    keep += 1;
                }
                self.series.truncate(keep);
                self.stride *= 2;
            }
            self.series.push([tick, u64::from(n)]);
        }
    }

    /// The summary; `None` when no particle message was seen.
    pub fn summary(&self) -> Option<ParticleSummary> {
        let last = self.last?;
        Some(ParticleSummary {
            min: self.min,
            max: self.max,
            mean: self.sum / self.messages as f64,
            last,
            series: self.series.clone(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_keep_the_range_the_mean_and_each_change() {
        let mut c = ParticleCounts::default();
        assert_eq!(c.summary(), None);
        for (tick, n) in [(0, 10_000), (10, 10_000), (20, 600), (30, 600), (40, 2000)] {
            c.record(tick, n);
        }
        let s = c.summary().unwrap();
        assert_eq!((s.min, s.max, s.last), (600, 10_000, 2000));
        assert_eq!(s.mean, (2.0 * 10_000.0 + 2.0 * 600.0 + 2000.0) / 5.0);
        assert_eq!(s.series, vec![[0, 10_000], [20, 600], [40, 2000]]);
    }

    /// A long run that changes at every message stays within the room, spans the whole run and
    /// never reallocates.
    #[test]
    fn a_long_run_is_thinned_within_the_room() {
        let mut c = ParticleCounts::default();
        let room = c.series.capacity();
        for tick in 0..100_000u64 {
            c.record(tick, 100 + (tick % 2) as u32);
        }
        let s = c.summary().unwrap();
        assert!(s.series.len() <= MAX_COUNT_POINTS && s.series.len() > MAX_COUNT_POINTS / 4);
        assert_eq!(s.series[0], [0, 100]);
        assert!(
            s.series.last().unwrap()[0] > 90_000,
            "{:?}",
            s.series.last()
        );
        assert!(s.series.windows(2).all(|w| w[0][0] < w[1][0]));
        assert_eq!(c.series.capacity(), room);
    }
}
