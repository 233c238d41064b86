//! A live stack served: the records the recorder's taps read (every sample, no decimation) go
//! to the channels, timed by the simulated time `tick × period` as a recording times them, so
//! a live client and `mole export --foxglove` of a recording of the same run see the same
//! messages at the same times. The newest truth's time is the server's time. The clients'
//! goals and paces go to `operator/goal` and `operator/pace` after each drain. With no client
//! connected the queues are read and forgotten (but the world's map, kept for the first client).

use crate::server::Served;
use mole_recorder::{Record, RecordSink};
use mole_runtime::RuntimeError;
use mole_types::topics;
use mole_view::Controls;

/// The records' sink: the server and the operator's publishers.
pub struct Relay {
    pub served: Served,
    /// The operator's publishers (none with the controls off).
    pub controls: Option<Controls>,
    /// The simulated step (ns): the world's map's, `1 / rate` until it came.
    pub period_ns: u64,
    /// The newest world tick: the tick of the operator's messages.
    pub tick: u64,
    /// Why publishing failed, if it did (the loop then ends).
    pub failed: Option<RuntimeError>,
}

impl Relay {
    pub fn new(served: Served, controls: Option<Controls>, rate_hz: f64) -> Relay {
        Relay {
            served,
            controls,
            period_ns: (1e9 / rate_hz).round() as u64,
            tick: 0,
            failed: None,
        }
    }

    fn take(&mut self, record: Record) {
        match record {
            Record::World { period_ns, .. } => self.period_ns = period_ns,
            Record::Message {
                topic, tick, data, ..
            } => {
                let log_time = tick.saturating_mul(self.period_ns);
                self.served.channels.log(topic, log_time, &data);
                if topic == topics::WORLD_TRUTH.name {
                    self.tick = tick;
                    self.served.handle.broadcast_time(log_time);
                }
            }
            Record::Event { tick, json } => {
                let log_time = tick.saturating_mul(self.period_ns);
                self.served.channels.log_event(log_time, &json);
            }
            Record::Flush => {}
        }
    }
}

impl RecordSink for Relay {
    fn send(&mut self, out: &mut Vec<Record>) -> bool {
        self.served.resend_subscribed();
        for record in out.drain(..) {
            self.take(record);
        }
        let inputs: Vec<_> = self.served.heard.inputs.try_iter().collect();
        if let Some(controls) = self.controls.as_mut()
            && !inputs.is_empty()
            && let Err(e) = controls.publish(inputs, self.tick)
        {
            self.failed = Some(e);
            return false;
        }
        true
    }

    fn flush(&mut self) -> bool {
        true
    }

    /// Only while a client is connected: otherwise the queues are read and forgotten.
    fn wants_samples(&self) -> bool {
        self.served.handle.client_count() > 0
    }
}
