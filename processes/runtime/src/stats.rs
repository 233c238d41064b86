//! Per-port counters and latency histograms, published on `stack/stats` once a second.

use core::cell::RefCell;
use hdrhistogram::Histogram;
use mole_types::{DIRECTION_PUBLISH, DIRECTION_SUBSCRIBE, MAX_TOPIC_STATS, Stats, TopicStats};
use std::rc::Rc;

/// Highest latency the histograms track (10 s, in µs); slower samples saturate.
const MAX_LATENCY_US: u64 = 10_000_000;

pub(crate) struct PortStats {
    topic: &'static str,
    direction: u32,
    count: u64,
    dropped: u64,
    invalid: u64,
    window_count: u64,
    latency_us: Histogram<u64>,
}

/// The statistics of every port of one process. Ports hold a handle and count into it.
#[derive(Clone, Default)]
pub struct StatsRegistry {
    ports: Rc<RefCell<Vec<PortStats>>>,
}

/// A port's slot in the registry.
#[derive(Clone)]
pub(crate) struct PortHandle {
    registry: StatsRegistry,
    index: usize,
}

impl StatsRegistry {
    pub(crate) fn register(
        &self,
        topic: &'static str,
        publish: bool,
    ) -> Result<PortHandle, hdrhistogram::CreationError> {
        let latency_us = Histogram::new_with_bounds(1, MAX_LATENCY_US, 3)?;
        let mut ports = self.ports.borrow_mut();
        ports.push(PortStats {
            topic,
            direction: if publish {
                DIRECTION_PUBLISH
            } else {
                DIRECTION_SUBSCRIBE
            },
            count: 0,
            dropped: 0,
            invalid: 0,
            window_count: 0,
            latency_us,
        });
        Ok(PortHandle {
            registry: self.clone(),
            index: ports.len() - 1,
        })
    }

    /// The invalid samples the subscribers of `topic` dropped.
    pub(crate) fn invalid(&self, topic: &str) -> u64 {
        let ports = self.ports.borrow();
        let mine = ports.iter().filter(|p| p.topic == topic);
        mine.filter(|p| p.direction == DIRECTION_SUBSCRIBE)
            .map(|p| p.invalid)
            .sum()
    }

    /// Writes every port's counters into `out` (all but header, process, pid, cpu, rss, steps)
    /// and starts a new window of `window_s` seconds.
    pub fn write_and_reset_window(&self, out: &mut Stats, window_s: f64) {
        let mut ports = self.ports.borrow_mut();
        let n = ports.len().min(MAX_TOPIC_STATS);
        out.n_topics = n as u32;
        for (slot, port) in out.topics.iter_mut().zip(ports.iter_mut()).take(n) {
            *slot = TopicStats::default();
            mole_types::write_name(&mut slot.topic, port.topic);
            slot.direction = port.direction;
            slot.count = port.count;
            slot.dropped = port.dropped;
            slot.invalid = port.invalid;
            slot.rate_hz = if window_s > 0.0 {
                (port.window_count as f64 / window_s) as f32
            } else {
                0.0
            };
            if !port.latency_us.is_empty() {
                slot.latency_p50_us = port.latency_us.value_at_quantile(0.5) as f32;
                slot.latency_p99_us = port.latency_us.value_at_quantile(0.99) as f32;
                slot.latency_max_us = port.latency_us.max() as f32;
            }
            port.window_count = 0;
            port.latency_us.reset();
        }
    }

    /// Total invalid messages over every port (for tests and logs).
    pub fn invalid_total(&self) -> u64 {
        self.ports.borrow().iter().map(|p| p.invalid).sum()
    }
}

impl PortHandle {
    fn with(&self, f: impl FnOnce(&mut PortStats)) {
        if let Some(port) = self.registry.ports.borrow_mut().get_mut(self.index) {
            f(port);
        }
    }
    pub(crate) fn counted(&self, latency_ns: Option<u64>) {
        self.with(|p| {
            p.count += 1;
            p.window_count += 1;
            if let Some(ns) = latency_ns {
                p.latency_us
                    .saturating_record((ns / 1000).clamp(1, MAX_LATENCY_US));
            }
        });
    }
    pub(crate) fn dropped(&self, n: u64) {
        self.with(|p| p.dropped += n);
    }
    pub(crate) fn invalid(&self) {
        self.with(|p| p.invalid += 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_report_rate_and_latency_then_reset() {
        let registry = StatsRegistry::default();
        let scan = registry.register("sensing/scan", false).unwrap();
        let cmd = registry.register("planning/cmd", true).unwrap();
        for i in 1..=100u64 {
            scan.counted(Some(i * 1000));
        }
        scan.dropped(2);
        scan.invalid();
        cmd.counted(None);
        let mut out: Box<Stats> = bytemuck::zeroed_box();
        registry.write_and_reset_window(&mut out, 2.0);
        assert_eq!(out.n_topics, 2);
        let s = &out.topics[0];
        assert_eq!(mole_types::read_name(&s.topic), "sensing/scan");
        assert_eq!((s.count, s.dropped, s.invalid), (100, 2, 1));
        assert_eq!(s.rate_hz, 50.0);
        assert!(
            (s.latency_p50_us - 50.0).abs() <= 1.0,
            "{}",
            s.latency_p50_us
        );
        assert!((s.latency_max_us - 100.0).abs() <= 1.0);
        assert_eq!(out.topics[1].direction, DIRECTION_PUBLISH);
        registry.write_and_reset_window(&mut out, 1.0);
        assert_eq!(out.topics[0].rate_hz, 0.0);
        assert_eq!(out.topics[0].count, 100, "counts are lifetime totals");
        assert_eq!(registry.invalid_total(), 1);
    }
}
