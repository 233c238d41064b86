//! What a running stack is, seen from its services alone: a tool that attaches to a stack it did
//! not start (`mole record --namespace NS`) must open its topics with the stack's clock mode.

use crate::clock::ClockMode;
use iceoryx2::prelude::*;
use iceoryx2::service::static_config::messaging_pattern::MessagingPattern as Recorded;
use mole_types::topics;

/// The clock mode of the stack in `namespace`, from its `world/truth` service: a realtime
/// topic's queues drop their oldest sample when full, a lockstep one's make the publisher wait.
/// `None` when the namespace has no such service (no stack runs there).
pub fn stack_clock_mode(namespace: &str) -> Option<ClockMode> {
    let name = topics::service_name(namespace, topics::WORLD_TRUTH.name);
    let name: ServiceName = name.as_str().try_into().ok()?;
    let details = ipc::Service::details(
        &name,
        Config::global_config(),
        MessagingPattern::PublishSubscribe,
    )
    .ok()??;
    match details.static_details.messaging_pattern() {
        Recorded::PublishSubscribe(config) => Some(match config.has_safe_overflow() {
            true => ClockMode::Realtime,
            false => ClockMode::Lockstep,
        }),
        _ => None,
    }
}
