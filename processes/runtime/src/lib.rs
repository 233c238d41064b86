//! The one place in mole that touches iceoryx2.
//!
//! A process main reads as its dataflow: [`Process`] (its node in a namespace) → a trigger and
//! inputs, each read by a [`Rule`] → outputs ([`Publisher`], written in place) → `run` with the
//! algorithm's `init` and `step`; the runtime waits, gates each step by the clock mode, joins a
//! run under way and takes over. Underneath: [`Context`], typed [`Subscriber`]s and a
//! [`WaitSet`] that sleeps until data, a deadline or a shutdown.
//!
//! - Every publish also wakes the topic's subscribers, so they sleep in a WaitSet: no busy
//!   loops, no sleep-polling. A mole node is rung on its doorbell (one named pipe per node), any
//!   other program through the topic's event service (`doorbell.rs`).
//! - iceoryx2's own signal handling is disabled on nodes; SIGINT/SIGTERM go to a `ctrlc`
//!   handler that sets the shutdown flag (iceoryx2 would silently replace it otherwise). The
//!   [`WaitSet`] polls the listeners' sockets itself: iceoryx2's allocates on every wake-up.
//! - Dead nodes' stale resources are cleaned when a process starts.
//! - Per-topic statistics (rate, dropped, invalid, latency from `origin_ns`) are published on
//!   `stack/stats` once a second.
//! - `stack/control` (request-response) carries `mole swap` / `mole stop` / `mole param` to the
//!   launcher; `stack/params` carries a setting changed while a process runs to it (`params.rs`).

mod admin;
mod alloc_counter;
mod clock;
mod context;
mod control;
mod discover;
mod doorbell;
mod error;
mod faults;
mod harness;
mod keep;
mod observe;
mod params;
mod ports;
mod source;
mod stats;
mod step;
mod time;
mod waitset;

pub use admin::{
    HALF_MADE_AGE, NodeCensus, cleanup_dead_nodes, list_topics, live_nodes_in_namespace,
    node_census,
};
pub use alloc_counter::{CountingAllocator, allocations_during};
pub use clock::{ClockMode, parse_point};
pub use context::{CommonArgs, Context, PayloadLayout, STUCK_CONSUMER, layout_mismatch};
pub use control::{ControlCall, ControlClient, ControlServer};
pub use discover::stack_clock_mode;
pub use doorbell::Ringer;
pub use error::{BadInput, RuntimeError, exit_code};
pub use harness::{Harness, same_payload};
pub use keep::{LastSamples, SaveRequest, read_resume_file, resume_file};
pub use observe::Observation;
pub use params::{MAX_PENDING, ScheduledChange, Tuning};
pub use ports::{Publisher, Subscriber, Waker};
pub use source::{ClockEvent, Flow, LOCKSTEP_RESEND, REPLY_TIMEOUT};
pub use stats::StatsRegistry;
pub use step::{
    In, Order, Process, Rule, Start, Step, TAKEOVER_GRACE, Trigger, rule_table, run_role,
};
pub use time::{init_tracing, now_ns, timed_ns};
pub use waitset::{Attachment, WaitSet, Wake};
