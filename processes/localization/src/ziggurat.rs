//! Standard normal draws four at a time, for the particle filter's motion step: four Xoshiro256++
//! streams side by side on `u64` lanes feed Marsaglia and Tsang's ziggurat with 256 layers
//! (Marsaglia & Tsang 2000, "The Ziggurat Method for Generating Random Variables").
//!
//! Deviation from a scalar ziggurat (`rand_distr::StandardNormal`): the four lanes' rectangle
//! test, which accepts 98.5 % of draws, runs on the lanes at once; a lane that lands in a wedge
//! or the tail finishes with the exact scalar tests on a fifth stream. The scalar form spends most
//! of its time waiting on its one generator's state, each draw on the one before.

use rand::rngs::Xoshiro256PlusPlus;
use rand::{Rng, RngExt, SeedableRng};
use wide::{f64x4, u64x4};

/// Layers of the ziggurat.
const LAYERS: usize = 256;
/// Where the base layer's tail starts, r, for 256 layers (Marsaglia & Tsang 2000, §2).
const R: f64 = 3.654_152_885_361_009;
/// The area of every layer, v, for 256 layers (Marsaglia & Tsang 2000, §2), with f unnormalised.
const V: f64 = 4.928_673_233_99e-3;

/// The unnormalised standard normal density, f(x) = exp(−x²/2).
fn density(x: f64) -> f64 {
    (-0.5 * x * x).exp()
}

/// Standard normal draws on four lanes, from four Xoshiro256++ streams and a fifth for the
/// wedges and the tail.
#[derive(Debug, Clone)]
pub struct ZigguratLanes {
    /// The four lanes' generator states s₀…s₃, lane k of each word being stream k's.
    state: [u64x4; 4],
    /// The stream that finishes draws outside a layer's rectangle.
    slow: Xoshiro256PlusPlus,
    /// Layer edges: x₀ = v/f(r) (the base layer's width, tail included), x₁ = r, then
    /// f(x_{i+1}) = f(x_i) + v/x_i, and x₂₅₆ = 0.
    x: [f64; LAYERS + 1],
    /// f(x_i) for each edge.
    f: [f64; LAYERS + 1],
}

impl ZigguratLanes {
    /// Five streams seeded from `rng`: the four lanes' states are its next 16 words, the slow
    /// stream's seed the 17th.
    pub fn from_rng(rng: &mut impl Rng) -> Self {
        let mut lanes = [[0u64; 4]; 4];
        for lane in &mut lanes {
            for word in lane.iter_mut() {
                *word = rng.next_u64();
            }
        }
        Self::from_lane_states(lanes, rng.next_u64())
    }

    /// Lane k draws the stream of Xoshiro256++ with state `lanes[k]` (a state of all zeros, which
    /// would stay zero, becomes [1, 0, 0, 0]), the slow stream that of `seed_from_u64(slow_seed)`.
    pub fn from_lane_states(lanes: [[u64; 4]; 4], slow_seed: u64) -> Self {
        let lanes = lanes.map(|s| if s == [0; 4] { [1, 0, 0, 0] } else { s });
        let state = std::array::from_fn(|w| u64x4::new(lanes.map(|s| s[w])));
        let mut x = [0.0; LAYERS + 1];
        x[0] = V / density(R);
        x[1] = R;
        for i in 1..LAYERS - 1 {
            x[i + 1] = (-2.0 * (V / x[i] + density(x[i])).ln()).sqrt();
        }
        x[LAYERS] = 0.0;
        Self {
            state,
            slow: Xoshiro256PlusPlus::seed_from_u64(slow_seed),
            x,
            f: x.map(density),
        }
    }

    /// The next word of each lane's stream (Xoshiro256++, Blackman & Vigna 2021).
    #[inline]
    pub fn next_words(&mut self) -> u64x4 {
        let rotl = |v: u64x4, k: u32| (v << k) | (v >> (64 - k));
        let [s0, s1, s2, s3] = &mut self.state;
        let out = rotl(*s0 + *s3, 23) + *s0;
        let t = *s1 << 17;
        *s2 ^= *s0;
        *s3 ^= *s1;
        *s1 ^= *s2;
        *s0 ^= *s3;
        *s2 ^= t;
        *s3 = rotl(*s3, 45);
        out
    }

    /// Fills `out` with independent standard normal draws.
    pub fn fill(&mut self, out: &mut [f64x4]) {
        for o in out {
            let words = self.next_words();
            // u uniform on [−1, 1) from the top 52 bits (the exponent of 2 gives [2, 4)), the
            // layer from the low 8 bits.
            let u =
                wide::bytemuck::cast::<u64x4, f64x4>((words >> 12) | u64x4::splat(2f64.to_bits()))
                    - f64x4::splat(3.0);
            let layer = (words & u64x4::splat(LAYERS as u64 - 1)).to_array();
            let width = f64x4::new(layer.map(|i| self.x[i as usize]));
            let inner = f64x4::new(layer.map(|i| self.x[i as usize + 1]));
            let z = u * width;
            let core = z.abs().simd_lt(inner);
            *o = if core.all() {
                z
            } else {
                let (core, z) = (core.to_bitmask(), z.to_array());
                f64x4::new(std::array::from_fn(|k| {
                    if core & (1 << k) != 0 {
                        z[k]
                    } else {
                        self.finish(layer[k] as usize, z[k])
                    }
                }))
            };
        }
    }

    /// A draw z = u·x_i of layer i that fell outside the layer's rectangle: the tail when i = 0,
    /// otherwise the wedge test; when that rejects, whole new draws from the slow stream until
    /// one is accepted.
    #[cold]
    fn finish(&mut self, mut layer: usize, mut z: f64) -> f64 {
        loop {
            if z.abs() < self.x[layer + 1] {
                return z;
            }
            if layer == 0 {
                return self.tail().copysign(z);
            }
            let y = self.f[layer] + self.slow.random::<f64>() * (self.f[layer + 1] - self.f[layer]);
            if y < density(z) {
                return z;
            }
            let word = self.slow.next_u64();
            let u = f64::from_bits((word >> 12) | 2f64.to_bits()) - 3.0;
            layer = (word & (LAYERS as u64 - 1)) as usize;
            z = u * self.x[layer];
        }
    }

    /// A draw of |X| beyond r (Marsaglia 1964): x = −ln(U₁)/r, y = −ln(U₂) until 2y > x², then
    /// r + x.
    fn tail(&mut self) -> f64 {
        loop {
            // 1 − U lies in (0, 1], so its logarithm is finite.
            let x = -(1.0 - self.slow.random::<f64>()).ln() / R;
            let y = -(1.0 - self.slow.random::<f64>()).ln();
            if 2.0 * y > x * x {
                return R + x;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use statrs::distribution::{ContinuousCDF, Normal};

    fn lanes(seed: u64) -> ZigguratLanes {
        ZigguratLanes::from_rng(&mut Xoshiro256PlusPlus::seed_from_u64(seed))
    }

    fn draws(z: &mut ZigguratLanes, n: usize) -> Vec<f64> {
        let mut out = vec![f64x4::ZERO; n.div_ceil(4)];
        z.fill(&mut out);
        let mut v: Vec<f64> = wide::bytemuck::cast_slice(&out).to_vec();
        v.truncate(n);
        v
    }

    #[test]
    fn each_lane_is_the_reference_xoshiro256plusplus_stream() {
        let states = [
            [1, 2, 3, 4],
            [5, 6, 7, 8],
            [u64::MAX, 0, 42, 7],
            [0, 0, 0, 0],
        ];
        let mut z = ZigguratLanes::from_lane_states(states, 9);
        let mut reference = [states[0], states[1], states[2], [1, 0, 0, 0]].map(|s| {
            let mut bytes = [0u8; 32];
            for (w, word) in s.iter().enumerate() {
                bytes[8 * w..8 * w + 8].copy_from_slice(&word.to_le_bytes());
            }
            Xoshiro256PlusPlus::from_seed(bytes)
        });
        for _ in 0..1000 {
            let words = z.next_words().to_array();
            for (k, r) in reference.iter_mut().enumerate() {
                assert_eq!(words[k], r.next_u64(), "lane {k}");
            }
        }
    }

    #[test]
    fn the_layers_close_at_the_mode() {
        let z = lanes(1);
        // The top layer's ceiling f(x₂₅₅) + v/x₂₅₅ is the density's peak, f(0) = 1: r and v agree.
        let top = z.f[LAYERS - 1] + V / z.x[LAYERS - 1];
        assert!((top - 1.0).abs() < 1e-9, "top of the ziggurat at {top}");
        assert!(
            z.x.windows(2).skip(1).all(|w| w[0] > w[1]),
            "edges not decreasing"
        );
    }

    /// Kolmogorov–Smirnov against Φ on 2²⁰ draws: D is at most 1.95/√n with probability
    /// 0.999 under the null (the draws are seeded, so this is one fixed sample).
    #[test]
    fn the_draws_are_standard_normal() {
        let n = 1 << 20;
        let mut v = draws(&mut lanes(7), n);
        v.sort_by(f64::total_cmp);
        let phi = Normal::standard();
        let d = v
            .iter()
            .enumerate()
            .map(|(i, &x)| {
                let c = phi.cdf(x);
                (c - i as f64 / n as f64).max((i + 1) as f64 / n as f64 - c)
            })
            .fold(0.0, f64::max);
        assert!(d < 1.95 / (n as f64).sqrt(), "KS distance {d}");
        // The tail beyond r, where only the tail sampler draws: 2(1 − Φ(r)) of the draws, within
        // five binomial standard deviations.
        let p = 2.0 * phi.sf(R);
        let beyond = v.iter().filter(|x| x.abs() > R).count() as f64;
        let sd = (n as f64 * p * (1.0 - p)).sqrt();
        assert!(
            (beyond - n as f64 * p).abs() < 5.0 * sd,
            "{beyond} draws beyond r, expected {:.0} ± {sd:.0}",
            n as f64 * p
        );
    }

    /// Pearson's χ² over 402 bins (400 of width 0.02 on [−4, 4] and the two tails) on 2²² draws,
    /// fine enough to see the wedges, which hold about 1 % of the mass in thin slivers. The
    /// bound is the χ²₄₀₁ quantile 1 − 10⁻⁴ (its normal approximation 401 + 3.72·√802, rounded down).
    #[test]
    fn the_draws_fill_the_wedges() {
        let n = 1 << 22;
        let (bins, lo, width) = (400, -4.0, 0.02);
        let mut counts = vec![0u64; bins + 2];
        for x in draws(&mut lanes(13), n) {
            let b = ((x - lo) / width).floor();
            let slot = if b < 0.0 {
                0
            } else {
                (b as usize).min(bins) + 1
            };
            counts[slot.min(bins + 1)] += 1;
        }
        let phi = Normal::standard();
        let edge = |b: usize| lo + b as f64 * width;
        let chi2: f64 = counts
            .iter()
            .enumerate()
            .map(|(slot, &c)| {
                let p = match slot {
                    0 => phi.cdf(lo),
                    s if s == bins + 1 => phi.sf(edge(bins)),
                    s => phi.cdf(edge(s)) - phi.cdf(edge(s - 1)),
                };
                let e = n as f64 * p;
                (c as f64 - e).powi(2) / e
            })
            .sum();
        assert!(chi2 < 506.0, "χ² = {chi2:.0} over {} bins", bins + 2);
    }

    #[test]
    fn lanes_and_successive_draws_are_uncorrelated() {
        let n = 1 << 18;
        let v = draws(&mut lanes(11), n);
        let corr = |lag: usize| {
            let m = n - lag;
            v[..m]
                .iter()
                .zip(&v[lag..])
                .map(|(a, b)| a * b)
                .sum::<f64>()
                / m as f64
        };
        // Lag 1 pairs neighbouring lanes, lag 4 a lane with its own next draw; |ρ| < 5/√n.
        for lag in [1, 2, 3, 4, 5] {
            assert!(
                corr(lag).abs() < 5.0 / (n as f64).sqrt(),
                "lag {lag}: ρ = {}",
                corr(lag)
            );
        }
    }
}
