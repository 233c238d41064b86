//! What the launcher learns from `stack/stats` over a run: CPU time and peak memory per process,
//! rate and latency per topic and subscriber (for `mole bench stack` and `mole top`).

use mole_types::{DIRECTION_SUBSCRIBE, Stats, read_name};
use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

/// CPU and memory of one role over the run (summed over restarts).
#[derive(Debug, Clone, Serialize)]
pub struct ProcessUsage {
    pub role: String,
    /// CPU time (user + system) over the run (s).
    pub cpu_s: f64,
    /// CPU time over wall time between the first and last report, in % of one core.
    pub cpu_percent: f64,
    /// Peak resident set size (MiB).
    pub peak_rss_mib: f64,
    /// Steps the process handled.
    pub steps: u64,
    /// Per step, averaged over the run (µs): CPU in the process's own step function (its
    /// algorithm and publishes), in the runtime around it (waiting, receiving, checking,
    /// statistics), and the kernel's share of both (system time).
    pub per_step: StepCost,
}

/// Where one process's CPU goes per step (µs), from its `stack/stats`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct StepCost {
    /// In the step function (`Context::timed_step`).
    pub step_us: f64,
    /// Around it: the process's CPU less its step function's.
    pub runtime_us: f64,
    /// System time, part of the two above.
    pub kernel_us: f64,
}

/// Latency from `origin_ns` to receipt at one subscriber, over the run.
#[derive(Debug, Clone, Serialize)]
pub struct HopLatency {
    pub topic: String,
    /// The subscribing process.
    pub at: String,
    /// Mean message rate over the windows that saw traffic (Hz).
    pub rate_hz: f64,
    /// Median of the one-second windows' p50 (µs).
    pub p50_us: f64,
    /// Largest one-second window p99 (µs).
    pub p99_us: f64,
    /// Largest latency seen (µs).
    pub max_us: f64,
    pub dropped: u64,
    pub invalid: u64,
}

#[derive(Debug, Default)]
struct RoleState {
    pid: u32,
    /// CPU of earlier incarnations (restarts), ns.
    cpu_before_ns: u64,
    cpu_first_ns: Option<u64>,
    cpu_last_ns: u64,
    /// Step-function and system CPU: earlier incarnations' and this one's, ns.
    step_before_ns: u64,
    step_last_ns: u64,
    system_before_ns: u64,
    system_last_ns: u64,
    first_seen: Option<Instant>,
    last_seen: Option<Instant>,
    max_rss_bytes: u64,
    steps: u64,
}

#[derive(Debug, Default)]
struct TopicState {
    p50s: Vec<f64>,
    rates: Vec<f64>,
    p99_max: f64,
    max: f64,
    dropped: u64,
    invalid: u64,
}

impl RoleState {
    /// CPU per step over the run, given the run's total CPU (`cpu_ns`).
    fn per_step(&self, cpu_ns: u64) -> StepCost {
        if self.steps == 0 {
            return StepCost::default();
        }
        let step_ns = self.step_before_ns + self.step_last_ns;
        let per = |ns: u64| ns as f64 / 1e3 / self.steps as f64;
        StepCost {
            step_us: per(step_ns),
            runtime_us: per(cpu_ns.saturating_sub(step_ns)),
            kernel_us: per(self.system_before_ns + self.system_last_ns),
        }
    }
}

/// Accumulates `stack/stats` messages.
#[derive(Debug, Default)]
pub struct StatsCollector {
    roles: BTreeMap<String, RoleState>,
    hops: BTreeMap<(String, String), TopicState>,
}

impl StatsCollector {
    /// Takes one process's statistics.
    pub fn record(&mut self, stats: &Stats) {
        let role = read_name(&stats.process).into_owned();
        let now = Instant::now();
        let state = self.roles.entry(role.clone()).or_default();
        if state.pid != stats.pid {
            // A new incarnation: keep what the old one used.
            state.cpu_before_ns += state.cpu_last_ns;
            state.step_before_ns += state.step_last_ns;
            state.system_before_ns += state.system_last_ns;
            (state.cpu_last_ns, state.step_last_ns, state.system_last_ns) = (0, 0, 0);
            state.pid = stats.pid;
        }
        if state.cpu_first_ns.is_none() {
            state.cpu_first_ns = Some(stats.cpu_ns);
            state.first_seen = Some(now);
        }
        state.cpu_last_ns = stats.cpu_ns;
        state.step_last_ns = stats.step_cpu_ns;
        state.system_last_ns = stats.system_ns;
        state.last_seen = Some(now);
        state.max_rss_bytes = state.max_rss_bytes.max(stats.max_rss_bytes);
        state.steps = state.steps.max(stats.steps);
        for t in stats
            .topics()
            .iter()
            .filter(|t| t.direction == DIRECTION_SUBSCRIBE)
        {
            let hop = self
                .hops
                .entry((read_name(&t.topic).into_owned(), role.clone()))
                .or_default();
            hop.dropped = hop.dropped.max(t.dropped);
            hop.invalid = hop.invalid.max(t.invalid);
            if t.rate_hz > 0.0 {
                hop.rates.push(f64::from(t.rate_hz));
                hop.p50s.push(f64::from(t.latency_p50_us));
                hop.p99_max = hop.p99_max.max(f64::from(t.latency_p99_us));
                hop.max = hop.max.max(f64::from(t.latency_max_us));
            }
        }
    }

    /// Per-process CPU and memory, by role.
    pub fn processes(&self) -> Vec<ProcessUsage> {
        self.roles
            .iter()
            .map(|(role, s)| {
                let cpu_ns = s.cpu_before_ns + s.cpu_last_ns;
                let wall = match (s.first_seen, s.last_seen) {
                    (Some(a), Some(b)) => b.duration_since(a).as_secs_f64(),
                    _ => 0.0,
                };
                let window_cpu = cpu_ns.saturating_sub(s.cpu_first_ns.unwrap_or(0)) as f64 / 1e9;
                ProcessUsage {
                    role: role.clone(),
                    cpu_s: cpu_ns as f64 / 1e9,
                    cpu_percent: if wall > 0.0 {
                        100.0 * window_cpu / wall
                    } else {
                        0.0
                    },
                    peak_rss_mib: s.max_rss_bytes as f64 / (1024.0 * 1024.0),
                    steps: s.steps,
                    per_step: s.per_step(cpu_ns),
                }
            })
            .collect()
    }

    /// Per-topic, per-subscriber latency over the run.
    pub fn hops(&self) -> Vec<HopLatency> {
        self.hops
            .iter()
            .filter(|(_, h)| !h.p50s.is_empty())
            .map(|((topic, at), h)| {
                let mut p50s = h.p50s.clone();
                p50s.sort_by(f64::total_cmp);
                HopLatency {
                    topic: topic.clone(),
                    at: at.clone(),
                    rate_hz: h.rates.iter().sum::<f64>() / h.rates.len() as f64,
                    p50_us: p50s[p50s.len() / 2],
                    p99_us: h.p99_max,
                    max_us: h.max,
                    dropped: h.dropped,
                    invalid: h.invalid,
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mole_types::write_name;

    fn stats(role: &str, pid: u32, cpu_ns: u64, p50: f32) -> Box<Stats> {
        let mut s: Box<Stats> = bytemuck::zeroed_box();
        write_name(&mut s.process, role);
        s.pid = pid;
        s.cpu_ns = cpu_ns;
        s.max_rss_bytes = 4 << 20;
        s.n_topics = 1;
        write_name(&mut s.topics[0].topic, "world/truth");
        s.topics[0].rate_hz = 100.0;
        s.topics[0].latency_p50_us = p50;
        s.topics[0].latency_p99_us = p50 * 2.0;
        s.topics[0].latency_max_us = p50 * 3.0;
        s
    }

    #[test]
    fn the_cost_per_step_splits_the_cpu_summed_over_restarts() {
        let mut c = StatsCollector::default();
        let report = |pid, cpu_ns, step_cpu_ns, system_ns, steps| {
            let mut s = stats("mapping", pid, cpu_ns, 10.0);
            (s.step_cpu_ns, s.system_ns, s.steps) = (step_cpu_ns, system_ns, steps);
            s
        };
        c.record(&report(10, 4_000_000, 1_000_000, 2_000_000, 100));
        // A restart: the new incarnation counts from zero, and has handled 200 steps in all.
        c.record(&report(11, 2_000_000, 1_000_000, 500_000, 200));
        let cost = c.processes()[0].per_step;
        // 6 ms of CPU over 200 steps: 10 µs in the step, 20 µs around it, 12.5 µs in the kernel.
        assert!((cost.step_us - 10.0).abs() < 1e-9, "{cost:?}");
        assert!((cost.runtime_us - 20.0).abs() < 1e-9, "{cost:?}");
        assert!((cost.kernel_us - 12.5).abs() < 1e-9, "{cost:?}");
    }

    #[test]
    fn cpu_is_summed_over_restarts_and_latency_over_windows() {
        let mut c = StatsCollector::default();
        c.record(&stats("sensing", 10, 1_000_000_000, 10.0));
        c.record(&stats("sensing", 10, 2_000_000_000, 30.0));
        c.record(&stats("sensing", 11, 500_000_000, 20.0));
        let p = &c.processes()[0];
        assert_eq!(p.role, "sensing");
        assert!((p.cpu_s - 2.5).abs() < 1e-9, "{}", p.cpu_s);
        assert!((p.peak_rss_mib - 4.0).abs() < 1e-9);
        let h = &c.hops()[0];
        assert_eq!(
            (h.topic.as_str(), h.at.as_str()),
            ("world/truth", "sensing")
        );
        assert_eq!(h.p50_us, 20.0);
        assert_eq!(h.p99_us, 60.0);
        assert_eq!(h.max_us, 90.0);
        assert_eq!(h.rate_hz, 100.0);
    }
}
