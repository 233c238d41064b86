//! Percentiles of unfiltered latency samples.

use serde::Serialize;

/// The distribution of one measurement, in microseconds (nearest-rank percentiles of every
/// sample: nothing is filtered or trimmed).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Summary {
    /// Number of samples.
    pub count: usize,
    pub p50_us: f64,
    pub p99_us: f64,
    pub p999_us: f64,
    pub max_us: f64,
    pub mean_us: f64,
}

impl Summary {
    /// Summarises nanosecond samples (sorts them in place); `None` when there are none.
    pub fn from_ns(samples: &mut [u64]) -> Option<Summary> {
        if samples.is_empty() {
            return None;
        }
        samples.sort_unstable();
        let sum: u128 = samples.iter().map(|&s| u128::from(s)).sum();
        let us = |ns: u64| ns as f64 / 1000.0;
        Some(Summary {
            count: samples.len(),
            p50_us: us(nearest_rank(samples, 0.50)),
            p99_us: us(nearest_rank(samples, 0.99)),
            p999_us: us(nearest_rank(samples, 0.999)),
            max_us: us(samples[samples.len() - 1]),
            mean_us: sum as f64 / samples.len() as f64 / 1000.0,
        })
    }
}

/// The nearest-rank percentile `q` of sorted, non-empty samples: the smallest value with at
/// least `q·n` samples at or below it.
fn nearest_rank(sorted: &[u64], q: f64) -> u64 {
    let n = sorted.len();
    let rank = (q * n as f64).ceil() as usize;
    sorted[rank.clamp(1, n) - 1]
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn percentiles_of_one_to_a_thousand() {
        let mut samples: Vec<u64> = (1..=1000).rev().map(|i| i * 1000).collect();
        let s = Summary::from_ns(&mut samples).expect("non-empty");
        assert_eq!(s.count, 1000);
        assert_eq!(s.p50_us, 500.0);
        assert_eq!(s.p99_us, 990.0);
        assert_eq!(s.p999_us, 999.0);
        assert_eq!(s.max_us, 1000.0);
        assert!((s.mean_us - 500.5).abs() < 1e-9);
    }

    #[test]
    fn one_sample_is_every_percentile_and_none_is_nothing() {
        let s = Summary::from_ns(&mut [2500]).expect("non-empty");
        assert_eq!((s.p50_us, s.p999_us, s.max_us), (2.5, 2.5, 2.5));
        assert!(Summary::from_ns(&mut []).is_none());
    }

    proptest! {
        #[test]
        fn percentiles_are_ordered_and_within_the_samples(
            mut samples in proptest::collection::vec(0u64..10_000_000, 1..300)
        ) {
            let lo = *samples.iter().min().unwrap_or(&0) as f64 / 1000.0;
            let s = Summary::from_ns(&mut samples).expect("non-empty");
            prop_assert!(lo <= s.p50_us);
            prop_assert!(s.p50_us <= s.p99_us && s.p99_us <= s.p999_us && s.p999_us <= s.max_us);
            prop_assert!(lo <= s.mean_us && s.mean_us <= s.max_us);
        }
    }
}
