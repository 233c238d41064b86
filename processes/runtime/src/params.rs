//! Settings changed while a process runs (`mole param set`, docs/settings.md). The launcher
//! publishes a [`ParamChange`] request on `stack/params`; before each step the role's runtime
//! takes in the requests for its role and applies each one due, through the process's own
//! `tune`, then publishes the outcome with the step it took effect before. A replay hands a
//! process the changes its recording holds at start (`changes` in `MOLE_SETTINGS`), and the
//! process applies each before the same step: so a lockstep recording replays them.

use crate::context::{CommonArgs, Context};
use crate::error::{BadInput, RuntimeError};
use crate::ports::{Publisher, Subscriber};
use mole_types::settings::Settings;
use mole_types::{
    PARAM_APPLIED, PARAM_REFUSED, PARAM_REQUESTED, ParamChange, Role, read_name, topics, write_name,
};
use serde::Deserialize;

/// Most requests a process holds for a later step (a replay's schedule, requests arriving
/// faster than steps); more are refused.
pub const MAX_PENDING: usize = 64;

/// One change a recording holds, as a replay hands it to the process (`changes` in
/// `MOLE_SETTINGS`).
#[derive(Debug, Clone, PartialEq, Deserialize, serde::Serialize)]
pub struct ScheduledChange {
    /// The step before which it applies.
    pub tick: u64,
    pub role: String,
    pub key: String,
    pub value: String,
}

/// A role's settings and the ports that change them while it runs: see [`crate::Process::run_tuned`].
pub struct Tuning<T> {
    role: Role,
    current: T,
    requests: Subscriber<ParamChange>,
    outcomes: Publisher<ParamChange>,
    /// Requests not yet due, in arrival order (room for [`MAX_PENDING`] from the start).
    pending: Vec<ParamChange>,
}

impl CommonArgs {
    /// The changes a replay scheduled for `role` (`changes` in `MOLE_SETTINGS`), in step order.
    pub fn scheduled_changes(&self, role: Role) -> Result<Vec<ScheduledChange>, BadInput> {
        let Some(text) = self.settings.as_deref().filter(|t| !t.trim().is_empty()) else {
            return Ok(Vec::new());
        };
        #[derive(Deserialize)]
        struct Changes {
            #[serde(default)]
            changes: Vec<ScheduledChange>,
        }
        let all: Changes = serde_json::from_str(text).map_err(|e| {
            BadInput(format!(
                "--settings ({}), `changes`: {e}",
                mole_types::env::SETTINGS
            ))
        })?;
        let mut mine: Vec<_> = all
            .changes
            .into_iter()
            .filter(|c| c.role == role.name())
            .collect();
        mine.sort_by_key(|c| c.tick);
        Ok(mine)
    }
}

impl<T: Settings> Tuning<T> {
    /// `role`'s settings from the arguments, checked, with the ports that change them and the
    /// changes a replay scheduled.
    pub(crate) fn new(ctx: &Context, args: &CommonArgs, role: Role) -> Result<Self, BadInput> {
        let current = args.settings::<T>(role)?;
        let defaults = T::default();
        let tuned: Vec<String> = T::keys()
            .into_iter()
            .filter_map(|k| {
                let value = current.get(&k.path)?;
                (defaults.get(&k.path).as_ref() != Some(&value))
                    .then(|| format!("{} = {value}", k.path))
            })
            .collect();
        if !tuned.is_empty() {
            tracing::info!("settings other than the defaults: {}", tuned.join(", "));
        }
        let scheduled = args.scheduled_changes(role)?;
        if scheduled.len() > MAX_PENDING {
            return Err(BadInput(format!(
                "{} changes scheduled for {role}: at most {MAX_PENDING}",
                scheduled.len()
            )));
        }
        let port = |e: RuntimeError| BadInput(format!("stack/params: {e}"));
        let mut pending = Vec::with_capacity(MAX_PENDING);
        for change in &scheduled {
            let mut request: ParamChange = bytemuck::Zeroable::zeroed();
            request.state = PARAM_REQUESTED;
            request.apply_at = change.tick;
            write_name(&mut request.role, &change.role);
            write_name(&mut request.key, &change.key);
            write_name(&mut request.value, &change.value);
            pending.push(request);
        }
        Ok(Tuning {
            role,
            current,
            requests: ctx.passive_subscriber(topics::STACK_PARAMS).map_err(port)?,
            outcomes: ctx.publisher(topics::STACK_PARAMS).map_err(port)?,
            pending,
        })
    }
}

impl<T: Settings> Tuning<T> {
    /// The settings in force.
    pub fn settings(&self) -> &T {
        &self.current
    }

    /// Before step `k`: takes in the new requests for this role, then applies every one due
    /// (`apply_at` 0 or at most `k`) in arrival order through `tune`, and publishes each outcome.
    pub(crate) fn before_step<S>(
        &mut self,
        k: u64,
        state: &mut S,
        tune: &mut impl FnMut(&mut S, &T) -> Result<(), String>,
    ) -> Result<(), RuntimeError> {
        let (role, pending) = (self.role.name(), &mut self.pending);
        let mut overflow = 0usize;
        self.requests.drain(|m| {
            if m.state == PARAM_REQUESTED && read_name(&m.role) == role {
                if pending.len() < MAX_PENDING {
                    pending.push(*m);
                } else {
                    overflow += 1;
                }
            }
        });
        if overflow > 0 {
            tracing::warn!(
                overflow,
                "more setting requests than {MAX_PENDING} held: dropped"
            );
        }
        let mut i = 0;
        while i < self.pending.len() {
            let due = self.pending[i].apply_at;
            if due != 0 && due > k {
                i += 1;
                continue;
            }
            let request = self.pending.remove(i);
            let outcome = self.apply(&request, state, tune);
            match &outcome {
                Ok(()) => tracing::info!(
                    key = %read_name(&request.key),
                    value = %read_name(&request.value),
                    tick = k,
                    "setting changed"
                ),
                Err(why) => tracing::warn!(
                    key = %read_name(&request.key),
                    value = %read_name(&request.value),
                    "setting refused: {why}"
                ),
            }
            self.outcomes.publish(k, 0, |m| {
                *m = request;
                m.apply_at = k;
                m.text = [0; mole_types::PARAM_TEXT_LEN];
                match &outcome {
                    Ok(()) => m.state = PARAM_APPLIED,
                    Err(why) => {
                        m.state = PARAM_REFUSED;
                        write_name(&mut m.text, why);
                    }
                }
            })?;
        }
        Ok(())
    }

    /// Checks `request` against the settings (a known key, not fixed while running, a value of
    /// its kind within its bounds), hands the new settings to `tune` and keeps them if it took
    /// them.
    fn apply<S>(
        &mut self,
        request: &ParamChange,
        state: &mut S,
        tune: &mut impl FnMut(&mut S, &T) -> Result<(), String>,
    ) -> Result<(), String> {
        let (key, value) = (read_name(&request.key), read_name(&request.value));
        if let Some(why) = T::keys()
            .into_iter()
            .find(|k| k.path == key)
            .and_then(|k| k.fixed)
        {
            return Err(format!(
                "`{key}` cannot change while the process runs: {why}"
            ));
        }
        let new = self.current.with(&key, &value).map_err(|e| e.to_string())?;
        tune(state, &new)?;
        self.current = new;
        Ok(())
    }
}
