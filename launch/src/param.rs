//! `mole param list|get|set`: the settings of a running stack (docs/settings.md). The command
//! asks the launcher through `stack/control`; the launcher answers `list` and `get` from the
//! settings in force and hands a `set` it has checked to the role's process on `stack/params`,
//! which takes it before its next step (or refuses it, saying why) and says so on the same topic.

use crate::Failure;
use crate::settings::StackSettings;
use clap::{Args, Subcommand};
use mole_runtime::{Context, Publisher, RuntimeError, Subscriber, now_ns};
use mole_types::settings::{Key, Settings};
use mole_types::{
    CONTROL_FAILED, CONTROL_OK, CONTROL_PARAM, CONTROL_REFUSED, ControlRequest, PARAM_APPLIED,
    PARAM_REFUSED, PARAM_REQUESTED, ParamChange, read_name, topics, write_name,
};
use serde::Serialize;
use std::time::{Duration, Instant};

/// How long the launcher waits for a process to take a setting: it does at its next step.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(5);

#[derive(Debug, Clone, Args)]
pub struct ParamArgs {
    #[command(subcommand)]
    pub command: ParamCommand,
    /// Namespace of the running stack.
    #[arg(long, global = true, default_value = mole_types::env::DEFAULT_NAMESPACE)]
    pub namespace: String,
}

#[derive(Debug, Clone, Subcommand)]
pub enum ParamCommand {
    /// Every setting of a role with its value in force (`fixed`: it cannot change while the
    /// process runs).
    List { role: String },
    /// One setting's value in force.
    Get { role: String, key: String },
    /// Change a setting of a running process: checked by the launcher, taken by the process
    /// before its next step; prints the step it took effect at.
    Set {
        role: String,
        key: String,
        #[arg(allow_hyphen_values = true)]
        value: String,
    },
}

/// `mole param …`: exit 2 for a request the launcher refuses (an unknown role or key, a value
/// out of bounds, a fixed key), 1 when the process refused it or did not answer.
pub fn param(args: &ParamArgs) -> Result<(), Failure> {
    let words: Vec<&str> = match &args.command {
        ParamCommand::List { role } => vec!["list", role],
        ParamCommand::Get { role, key } => vec!["get", role, key],
        ParamCommand::Set { role, key, value } => vec!["set", role, key, value],
    };
    let mut request = ControlRequest::new(CONTROL_PARAM);
    if !request.set_argv(&words) {
        return Err(Failure::input("the key or value is too long"));
    }
    let timeout = ANSWER_TIMEOUT.as_secs_f64() + 5.0;
    let response = crate::control::call(&args.namespace, request, timeout)?;
    println!("{}", crate::control::answer(&response)?);
    Ok(())
}

/// A setting changed while the stack ran, for summary.json (`settings_changes`).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct SettingChange {
    /// The step before which the process took it.
    pub tick: u64,
    pub role: String,
    pub key: String,
    pub value: String,
}

/// The launcher's side: the settings in force, and the requests it hands to processes.
pub struct Tuner {
    settings: StackSettings,
    /// The changes a replay scheduled (handed to a restarted process again).
    scheduled: Vec<mole_runtime::ScheduledChange>,
    requests: Publisher<ParamChange>,
    answers: Subscriber<ParamChange>,
    sent: u32,
    /// Every change a process took, in order.
    pub changes: Vec<SettingChange>,
}

/// What a `mole param` request came to: the status of the response and its text.
pub type Answer = (u32, String);

impl Tuner {
    /// The launcher's tuner for a stack started with `settings`.
    pub fn new(
        ctx: &Context,
        settings: StackSettings,
        scheduled: Vec<mole_runtime::ScheduledChange>,
    ) -> Result<Tuner, RuntimeError> {
        Ok(Tuner {
            settings,
            scheduled,
            requests: ctx.publisher(topics::STACK_PARAMS)?,
            answers: ctx.passive_subscriber(topics::STACK_PARAMS)?,
            sent: 0,
            changes: Vec::new(),
        })
    }

    /// `MOLE_SETTINGS` for a process restarted now: the settings in force (the start's with
    /// every change `mole param` made) and a replay's schedule.
    pub fn settings_json(&self) -> String {
        self.settings.to_json_with(&self.scheduled)
    }

    /// Answers `mole param` with `words` (`list ROLE`, `get ROLE KEY`, `set ROLE KEY VALUE`).
    pub fn handle(&mut self, words: &[String]) -> Answer {
        let refused = |why: String| (CONTROL_REFUSED, why);
        let words: Vec<&str> = words.iter().map(String::as_str).collect();
        let role = match words.as_slice() {
            [_, role, ..] => *role,
            _ => return refused("expected list ROLE, get ROLE KEY or set ROLE KEY VALUE".into()),
        };
        // A role's keys are the stack's under its table; a role without a table has none.
        let prefix = format!("{role}.");
        let keys: Vec<Key> = StackSettings::keys()
            .into_iter()
            .filter_map(|k| {
                let path = k.path.strip_prefix(&prefix)?.to_owned();
                Some(Key { path, ..k })
            })
            .collect();
        if keys.is_empty() {
            return refused(format!(
                "role `{role}` has no settings: planning, localization or mapping"
            ));
        }
        let value_of = |key: &str| {
            self.settings
                .get(&format!("{role}.{key}"))
                .unwrap_or_else(|| "unset".to_owned())
        };
        match words.as_slice() {
            ["list", _] => {
                let lines: Vec<String> = keys
                    .iter()
                    .map(|k| {
                        let fixed = if k.fixed.is_some() { "  (fixed)" } else { "" };
                        format!("{} = {}{fixed}", k.path, value_of(&k.path))
                    })
                    .collect();
                (CONTROL_OK, lines.join("\n"))
            }
            ["get", _, key] => match keys.iter().any(|k| k.path == *key) {
                true => (CONTROL_OK, value_of(key)),
                false => refused(format!(
                    "{role} has no setting `{key}` (mole param list {role})"
                )),
            },
            ["set", _, key, value] => self.set(role, key, value, &keys),
            _ => refused("expected list ROLE, get ROLE KEY or set ROLE KEY VALUE".into()),
        }
    }

    /// Takes in the processes' answers on `stack/params`: every change applied joins
    /// [`Tuner::changes`] (a replay's scheduled ones too); returns the answer `mine` picks.
    pub fn follow(&mut self, mine: impl Fn(&ParamChange) -> bool) -> Option<ParamChange> {
        let (changes, mut picked) = (&mut self.changes, None);
        self.answers.drain(|m| {
            if m.state == PARAM_REQUESTED {
                return;
            }
            if m.state == PARAM_APPLIED {
                changes.push(SettingChange {
                    tick: m.apply_at,
                    role: read_name(&m.role).into_owned(),
                    key: read_name(&m.key).into_owned(),
                    value: read_name(&m.value).into_owned(),
                });
            }
            if mine(m) {
                picked = Some(*m);
            }
        });
        picked
    }

    /// Checks `role.key = value` against the settings in force, hands it to the role's process
    /// and waits for its answer.
    fn set(&mut self, role: &str, key: &str, value: &str, keys: &[Key]) -> Answer {
        let full = format!("{role}.{key}");
        let new = match self.settings.with(&full, value) {
            Ok(new) => new,
            Err(e) => return (CONTROL_REFUSED, e.to_string()),
        };
        if let Some(why) = keys
            .iter()
            .find(|k| k.path == key)
            .and_then(|k| k.fixed.as_ref())
        {
            return (
                CONTROL_REFUSED,
                format!("`{full}` cannot change while the process runs: {why}"),
            );
        }
        let value = new.get(&full).unwrap_or_else(|| value.to_owned());
        self.sent += 1;
        let (request, stamp) = (self.sent, now_ns());
        let sent = self.requests.publish(0, 0, |m| {
            (m.state, m.request, m.apply_at, m.requested_ns) = (PARAM_REQUESTED, request, 0, stamp);
            m.text = [0; mole_types::PARAM_TEXT_LEN];
            write_name(&mut m.role, role);
            write_name(&mut m.key, key);
            write_name(&mut m.value, &value);
        });
        if let Err(e) = sent {
            return (
                CONTROL_FAILED,
                format!("cannot publish on stack/params: {e}"),
            );
        }
        let deadline = Instant::now() + ANSWER_TIMEOUT;
        while Instant::now() < deadline {
            let outcome = self.follow(|m| m.request == request && m.requested_ns == stamp);
            match outcome {
                Some(m) if m.state == PARAM_APPLIED => {
                    self.settings = new;
                    return (
                        CONTROL_OK,
                        format!("{full} = {value} from step {}", m.apply_at),
                    );
                }
                Some(m) if m.state == PARAM_REFUSED => {
                    return (
                        CONTROL_FAILED,
                        format!("{role} refused {key} = {value}: {}", read_name(&m.text)),
                    );
                }
                _ => std::thread::sleep(Duration::from_millis(1)),
            }
        }
        (
            CONTROL_FAILED,
            format!(
                "{role} did not take {key} = {value} within {ANSWER_TIMEOUT:?}: its process takes \
                 no settings while it runs (one swapped in?), or the stack is paused"
            ),
        )
    }
}
