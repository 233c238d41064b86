//! The loop of an observer (the monitor, a viewer): it reads every sample of its inputs, in
//! order, at its own pace, and does something periodically.

use crate::context::thread_cpu_ns;
use crate::step::{In, Process, Start, follow_map};
use crate::waitset::Wake;
use mole_types::Message;
use std::time::{Duration, Instant};

type BoxError = Box<dyn std::error::Error>;

/// One wake-up of an observer.
pub struct Observation<'a> {
    process: &'a mut Process,
    periodic: bool,
    shutdown: bool,
    again_in: Option<Duration>,
}

impl Observation<'_> {
    /// Hands every new valid sample of `input` to `on_message`, in arrival order.
    pub fn drain<M: Message>(&mut self, input: In<M>, on_message: impl FnMut(&M)) -> usize {
        self.process.input_mut(input).drain(on_message)
    }

    /// The newest sample of `input` drained so far.
    pub fn latest<M: Message>(&mut self, input: In<M>) -> Option<&M> {
        self.process.input_mut(input).latest()
    }

    /// The tick of the newest sample of `input` drained so far.
    pub fn latest_tick<M: Message>(&mut self, input: In<M>) -> Option<u64> {
        self.latest(input).map(|m| m.header().tick)
    }

    /// Whether the observer's period has passed since the last periodic wake-up.
    pub fn periodic(&self) -> bool {
        self.periodic
    }

    /// Whether a shutdown was requested: the last wake-up.
    pub fn shutdown(&self) -> bool {
        self.shutdown
    }

    /// Wake again after `delay` at the latest (e.g. to wait briefly for stragglers).
    pub fn again_in(&mut self, delay: Duration) {
        self.again_in = Some(delay);
    }
}

impl Process {
    /// Declares an input an observer reads every sample of; `wakes` says whether its samples
    /// wake the observer (the others are read on those wake-ups). In realtime an observer is
    /// beside the loop: what wakes it is the loop's step closing, not these samples
    /// ([`Process::wakes_after_the_loop`]).
    pub fn observed<M: Message>(
        &mut self,
        topic: mole_types::Topic<M>,
        wakes: bool,
    ) -> Result<In<M>, crate::RuntimeError> {
        if !wakes {
            return self.add_input(topic, crate::Rule::Newest, false);
        }
        Ok(In::at(
            self.add_beside_the_loop(topic, crate::Rule::Newest)?,
        ))
    }

    /// Runs an observer until `on_wake` ends it or a shutdown comes: `init` once the world's map
    /// is in, then `on_wake` whenever a waking input is published and at least once a `period`.
    pub fn observe<S>(
        mut self,
        period: Duration,
        init: impl FnOnce(&Start) -> Result<S, BoxError>,
        mut on_wake: impl FnMut(&mut S, &mut Observation) -> Result<crate::Flow, BoxError>,
    ) -> Result<(), BoxError> {
        self.check_ports_against_the_graph(&[])?;
        let waitset = self.ctx.waitset()?;
        let mut wakers = std::mem::take(&mut self.wakers);
        wakers.push(self.map.waker());
        let _attached = waitset.attach_all(&wakers)?;
        self.ctx.ready();
        let (mut init, mut state) = (Some(init), None);
        let mut next_periodic = Instant::now() + period;
        let mut deadline = next_periodic;
        loop {
            let wake = waitset.wait(&mut self.ctx, Some(deadline))?;
            follow_map(&self.ctx, &mut self.map, &mut init, &mut state)?;
            let Some(state) = state.as_mut() else {
                self.discard_inputs();
                if wake == Wake::Shutdown {
                    return Ok(());
                }
                next_periodic = Instant::now() + period;
                deadline = next_periodic;
                continue;
            };
            let periodic = Instant::now() >= next_periodic;
            if periodic {
                next_periodic = Instant::now() + period;
            }
            let mut observation = Observation {
                process: &mut self,
                periodic,
                shutdown: wake == Wake::Shutdown,
                again_in: None,
            };
            // An observer's step is a wake with the map in: timed and counted like a step.
            let start = thread_cpu_ns();
            let flow = on_wake(state, &mut observation)?;
            let again_in = observation.again_in;
            self.ctx.add_step_cpu(start);
            self.ctx.count_step();
            if flow == crate::Flow::End {
                return Ok(());
            }
            deadline = match again_in {
                Some(delay) => next_periodic.min(Instant::now() + delay),
                None => next_periodic,
            };
            if wake == Wake::Shutdown {
                return Ok(());
            }
        }
    }
}
