//! The stack's graph ([`mole_types::graph::GRAPH`]) as Foxglove's connection graph: each role
//! publishes its outputs and subscribes to its inputs on their raw channels (`/mole/<topic>`),
//! every role writes `stack/stats`, which the monitor reads, and the launcher provides the
//! control services.

use crate::channels::raw_channel;
use crate::control::{STATUS_SERVICE, STOP_SERVICE, SWAP_SERVICE};
use foxglove::websocket::ConnectionGraph;
use mole_types::graph::{GRAPH, Role, nodes};
use mole_types::topics;
use std::collections::BTreeMap;

/// Who publishes and who subscribes to each topic, by the node names the stack's processes have.
pub fn topic_ends() -> BTreeMap<&'static str, (Vec<&'static str>, Vec<&'static str>)> {
    let mut ends: BTreeMap<&str, (Vec<&str>, Vec<&str>)> = BTreeMap::new();
    for spec in GRAPH {
        let role = spec.role.name();
        for topic in spec.outputs.iter().chain([&topics::STACK_STATS.name]) {
            ends.entry(topic).or_default().0.push(role);
        }
        for topic in spec.inputs {
            ends.entry(topic).or_default().1.push(role);
        }
    }
    let stats = ends.entry(topics::STACK_STATS.name).or_default();
    stats.1.push(Role::Monitor.name());
    stats.1.push(nodes::LAUNCHER);
    for topic in [topics::STACK_PROCESSES.name, topics::STACK_PARAMS.name] {
        ends.entry(topic).or_default().0.push(nodes::LAUNCHER);
    }
    // The operator's: a page of the view, or a Foxglove client through this server.
    for topic in [topics::OPERATOR_GOAL.name, topics::OPERATOR_PACE.name] {
        ends.entry(topic)
            .or_default()
            .0
            .extend([nodes::VIEW, nodes::FOXGLOVE]);
    }
    ends
}

/// The connection graph of the stack.
pub fn connection_graph() -> ConnectionGraph {
    let mut graph = ConnectionGraph::new();
    for (topic, (publishers, subscribers)) in topic_ends() {
        if !publishers.is_empty() {
            graph.set_published_topic(raw_channel(topic), publishers);
        }
        if !subscribers.is_empty() {
            graph.set_subscribed_topic(raw_channel(topic), subscribers);
        }
    }
    for service in [SWAP_SERVICE, STOP_SERVICE, STATUS_SERVICE] {
        graph.set_advertised_service(service, [nodes::LAUNCHER]);
    }
    graph
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every topic a role reads has a publisher in the graph.
    #[test]
    fn every_input_has_a_publisher() {
        for (topic, (publishers, subscribers)) in topic_ends() {
            if !subscribers.is_empty() {
                assert!(!publishers.is_empty(), "{topic} is read but never written");
            }
        }
        let (publishers, _) = &topic_ends()[topics::WORLD_TRUTH.name];
        assert_eq!(publishers, &vec!["world"]);
    }
}
