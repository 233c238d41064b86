//! What happened to the stack's processes, as the recorder writes it on [`EVENTS_TOPIC`]: a role
//! started, restarted after a crash, swapped for another process, exited or failed, a fault was
//! injected (`mole fault`, from `stack/faults`), a setting changed or refused while running
//! (`mole param set`, from `stack/params`), and samples the recorder lost.
//!
//! The process events come from `stack/processes`, which the launcher publishes once a second
//! with every role's pid, state and restart count (for `mole top`): a new pid with one restart
//! more is a restart, a new pid without is a swap. So the recorder needs nothing from the launcher
//! but what any observer of the stack sees, `mole record` attached to a running stack finds the
//! same events as `mole up --record`, and an event is placed within a second of when it happened.

use mole_types::{
    Fault, FaultKind, PARAM_APPLIED, PARAM_REFUSED, PROCESS_EXITED, PROCESS_FAILED,
    PROCESS_RESTARTING, ParamChange, Processes, read_name,
};
use serde_json::json;
use std::collections::BTreeMap;

/// The channel of events: JSON messages (message encoding `json`, schema encoding
/// `jsonschema`), which any MCAP viewer shows as they are.
pub const EVENTS_TOPIC: &str = mole_types::topics::STACK_EVENTS;
/// The events' schema name.
pub const EVENT_SCHEMA_NAME: &str = "mole.Event";
/// The events' JSON schema.
pub const EVENT_SCHEMA: &str = r#"{"type":"object","properties":{"tick":{"type":"integer","description":"the newest world tick when the recorder saw it"},"kind":{"type":"string","enum":["started","restarted","swapped","down","exited","failed","lost","fault","param"]},"role":{"type":"string"},"fault":{"type":"string","enum":["kill","stop","delay","drop","corrupt"],"description":"what `mole fault` did"},"id":{"type":"integer","description":"the fault's number in the run"},"target":{"type":"string","description":"the role or topic faulted"},"duration_s":{"type":"number"},"delay_ms":{"type":"number"},"fraction":{"type":"number"},"pid":{"type":"integer"},"old_pid":{"type":"integer"},"restarts":{"type":"integer"},"topic":{"type":"string"},"count":{"type":"integer","description":"samples lost before the recorder read them"},"key":{"type":"string","description":"the setting below its role (`mole param set`)"},"value":{"type":"string"},"applied":{"type":"boolean","description":"whether the process took it, before step `at`"},"at":{"type":"integer"},"why":{"type":"string","description":"why it was refused"}},"required":["tick","kind"]}"#;

/// One event.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A role's first process.
    Started { role: String, pid: u32 },
    /// A role's process died and the launcher is restarting it.
    Down { role: String, pid: u32 },
    /// A new process in a role after a crash.
    Restarted {
        role: String,
        old_pid: u32,
        pid: u32,
        restarts: u32,
    },
    /// A new process in a role without a crash: `mole swap`.
    Swapped {
        role: String,
        old_pid: u32,
        pid: u32,
    },
    /// A role's process ended and is not restarted.
    Exited { role: String, pid: u32 },
    /// The launcher gave up on a role.
    Failed { role: String },
    /// Samples of a topic that overflowed the recorder's queue before it read them.
    Lost { topic: String, count: u64 },
    /// A fault `mole fault` injected (`stack/faults`): its number, kind, target, how long
    /// (s), how long each sample was held (ms, a delay) and the fraction hit (a drop or a
    /// corruption).
    Fault {
        id: u32,
        fault: &'static str,
        target: String,
        duration_s: f64,
        delay_ms: f64,
        fraction: f64,
    },
    /// A setting a process took before step `at` (`mole param set`), or refused and why.
    Param {
        role: String,
        key: String,
        value: String,
        at: u64,
        refused: Option<String>,
    },
}

impl Event {
    /// The event as the JSON message written at `tick`.
    pub fn to_json(&self, tick: u64) -> String {
        let value = match self {
            Event::Started { role, pid } => {
                json!({"tick": tick, "kind": "started", "role": role, "pid": pid})
            }
            Event::Down { role, pid } => {
                json!({"tick": tick, "kind": "down", "role": role, "pid": pid})
            }
            Event::Restarted {
                role,
                old_pid,
                pid,
                restarts,
            } => json!({"tick": tick, "kind": "restarted", "role": role, "old_pid": old_pid,
                        "pid": pid, "restarts": restarts}),
            Event::Swapped { role, old_pid, pid } => {
                json!({"tick": tick, "kind": "swapped", "role": role, "old_pid": old_pid, "pid": pid})
            }
            Event::Exited { role, pid } => {
                json!({"tick": tick, "kind": "exited", "role": role, "pid": pid})
            }
            Event::Failed { role } => json!({"tick": tick, "kind": "failed", "role": role}),
            Event::Lost { topic, count } => {
                json!({"tick": tick, "kind": "lost", "topic": topic, "count": count})
            }
            Event::Fault {
                id,
                fault,
                target,
                duration_s,
                delay_ms,
                fraction,
            } => json!({"tick": tick, "kind": "fault", "fault": fault, "id": id,
                        "target": target, "duration_s": duration_s, "delay_ms": delay_ms,
                        "fraction": fraction}),
            Event::Param {
                role,
                key,
                value,
                at,
                refused,
            } => json!({"tick": tick, "kind": "param", "role": role, "key": key,
                        "value": value, "applied": refused.is_none(), "at": at,
                        "why": refused}),
        };
        value.to_string()
    }
}

impl Event {
    /// The event of a fault read on `stack/faults`.
    pub fn of_fault(fault: &Fault) -> Event {
        Event::Fault {
            id: fault.id,
            fault: fault.fault_kind().map_or("unknown", FaultKind::name),
            target: fault.target().into_owned(),
            duration_s: fault.end_ns.saturating_sub(fault.start_ns) as f64 / 1e9,
            delay_ms: fault.delay_ns as f64 / 1e6,
            fraction: fault.fraction,
        }
    }
}

impl Event {
    /// The event of a process's answer on `stack/params` (`None` for a request).
    pub fn of_param(change: &ParamChange) -> Option<Event> {
        let refused = match change.state {
            PARAM_APPLIED => None,
            PARAM_REFUSED => Some(read_name(&change.text).into_owned()),
            _ => return None,
        };
        Some(Event::Param {
            role: read_name(&change.role).into_owned(),
            key: read_name(&change.key).into_owned(),
            value: read_name(&change.value).into_owned(),
            at: change.apply_at,
            refused,
        })
    }
}

/// What the last `stack/processes` said of one role.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Seen {
    pid: u32,
    state: u32,
    restarts: u32,
}

/// Turns the launcher's `stack/processes` reports into events.
#[derive(Debug, Default)]
pub struct ProcessWatch {
    roles: BTreeMap<String, Seen>,
}

impl ProcessWatch {
    /// The events between the previous report and `report`.
    pub fn update(&mut self, report: &Processes) -> Vec<Event> {
        let mut events = Vec::new();
        for p in report.processes() {
            let role = read_name(&p.role).into_owned();
            let now = Seen {
                pid: p.pid,
                state: p.state,
                restarts: p.restarts,
            };
            let before = self.roles.get(&role).copied();
            // A role down between two processes reports pid 0: keep the last one.
            let kept = Seen {
                pid: if now.pid == 0 {
                    before.map_or(0, |b| b.pid)
                } else {
                    now.pid
                },
                ..now
            };
            self.roles.insert(role.clone(), kept);
            let was = before.unwrap_or(Seen {
                pid: 0,
                state: now.state,
                restarts: now.restarts,
            });
            if now.pid != 0 && now.pid != was.pid {
                events.push(match was.pid {
                    0 if now.restarts == was.restarts => Event::Started {
                        role: role.clone(),
                        pid: now.pid,
                    },
                    old_pid if now.restarts > was.restarts => Event::Restarted {
                        role: role.clone(),
                        old_pid,
                        pid: now.pid,
                        restarts: now.restarts,
                    },
                    old_pid => Event::Swapped {
                        role: role.clone(),
                        old_pid,
                        pid: now.pid,
                    },
                });
            }
            if now.state != was.state || before.is_none() {
                match now.state {
                    PROCESS_RESTARTING => events.push(Event::Down {
                        role: role.clone(),
                        pid: was.pid,
                    }),
                    PROCESS_EXITED => events.push(Event::Exited {
                        role: role.clone(),
                        pid: was.pid.max(now.pid),
                    }),
                    PROCESS_FAILED => events.push(Event::Failed { role: role.clone() }),
                    _ => {}
                }
            }
        }
        events
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mole_types::{PROCESS_RUNNING, write_name};

    fn report(rows: &[(&str, u32, u32, u32)]) -> Processes {
        let mut p: Processes = bytemuck::Zeroable::zeroed();
        p.n_processes = rows.len() as u32;
        for (slot, (role, pid, state, restarts)) in p.processes.iter_mut().zip(rows) {
            write_name(&mut slot.role, role);
            (slot.pid, slot.state, slot.restarts) = (*pid, *state, *restarts);
        }
        p
    }

    /// A role's first pid is a start, a new pid with one restart more a restart, a new pid
    /// without a swap; a report that changes nothing is no event.
    #[test]
    fn starts_restarts_and_swaps_are_told_apart() {
        let mut watch = ProcessWatch::default();
        let run = PROCESS_RUNNING;
        assert_eq!(
            watch.update(&report(&[("sensing", 10, run, 0), ("mapping", 0, 0, 0)])),
            vec![Event::Started {
                role: "sensing".into(),
                pid: 10
            }]
        );
        assert_eq!(watch.update(&report(&[("sensing", 10, run, 0)])), vec![]);
        assert_eq!(
            watch.update(&report(&[("sensing", 11, run, 1)])),
            vec![Event::Restarted {
                role: "sensing".into(),
                old_pid: 10,
                pid: 11,
                restarts: 1
            }]
        );
        assert_eq!(
            watch.update(&report(&[("sensing", 12, run, 1)])),
            vec![Event::Swapped {
                role: "sensing".into(),
                old_pid: 11,
                pid: 12
            }]
        );
    }

    /// A crash seen while the restart is pending is a `down`, then the restart follows.
    #[test]
    fn a_crash_seen_before_its_restart_is_down_then_restarted() {
        let mut watch = ProcessWatch::default();
        watch.update(&report(&[("world", 7, PROCESS_RUNNING, 0)]));
        assert_eq!(
            watch.update(&report(&[("world", 0, PROCESS_RESTARTING, 0)])),
            vec![Event::Down {
                role: "world".into(),
                pid: 7
            }]
        );
        let events = watch.update(&report(&[("world", 9, PROCESS_RUNNING, 1)]));
        assert!(
            matches!(
                events.as_slice(),
                [Event::Restarted {
                    old_pid: 7,
                    pid: 9,
                    restarts: 1,
                    ..
                }]
            ),
            "{events:?}"
        );
        let json = events[0].to_json(420);
        let value: serde_json::Value = serde_json::from_str(&json).expect("JSON");
        assert_eq!(value["tick"], 420);
        assert_eq!(value["kind"], "restarted");
        assert_eq!(value["role"], "world");
    }
}
