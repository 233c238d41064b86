//! Start order of the processes of a stack, from their `depends_on` lists; stop order, from the
//! graph's stop ranks.

use super::ProcessSpec;
use crate::LaunchError;
use mole_types::graph;

/// Topological order (Kahn 1962): each process after everything it depends on; among processes
/// that are ready at the same time, file order wins, so the order is stable and predictable.
///
/// Returns indices into `processes`. A cycle is an error that names the cycle.
pub fn start_order(processes: &[ProcessSpec]) -> Result<Vec<usize>, LaunchError> {
    let n = processes.len();
    let mut deps: Vec<Vec<usize>> = Vec::with_capacity(n);
    for (i, p) in processes.iter().enumerate() {
        if processes[..i].iter().any(|q| q.role == p.role) {
            return Err(LaunchError::DuplicateRole {
                role: p.role.clone(),
            });
        }
        let mut these = Vec::with_capacity(p.depends_on.len());
        for d in &p.depends_on {
            let j = processes.iter().position(|q| q.role == *d).ok_or_else(|| {
                LaunchError::UnknownDependency {
                    role: p.role.clone(),
                    dependency: d.clone(),
                }
            })?;
            these.push(j);
        }
        deps.push(these);
    }

    let mut placed = vec![false; n];
    let mut order = Vec::with_capacity(n);
    while order.len() < n {
        let ready = (0..n).find(|&i| !placed[i] && deps[i].iter().all(|&j| placed[j]));
        match ready {
            Some(i) => {
                placed[i] = true;
                order.push(i);
            }
            None => return Err(find_cycle(processes, &deps, &placed)),
        }
    }
    Ok(order)
}

/// The graph's stop order ([`mole_types::RoleSpec::stop_rank`]): the world first, so nothing
/// new is produced, the monitor last, so it can still write its files. Returns indices into
/// `processes`; a role the graph does not have (an extra observer) stops last.
pub fn stop_order(processes: &[ProcessSpec]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..processes.len()).collect();
    order.sort_by_key(|&i| graph::spec(&processes[i].role).map_or(u8::MAX, |s| s.stop_rank));
    order
}

/// Every unplaced process waits on at least one unplaced one, so walking "first unplaced
/// dependency" from any unplaced process must come back to a process already on the walk.
fn find_cycle(processes: &[ProcessSpec], deps: &[Vec<usize>], placed: &[bool]) -> LaunchError {
    let mut walk: Vec<usize> = Vec::new();
    let mut at = placed.iter().position(|&p| !p);
    while let Some(i) = at {
        if let Some(k) = walk.iter().position(|&w| w == i) {
            let mut cycle: Vec<String> = walk[k..]
                .iter()
                .map(|&w| processes[w].role.clone())
                .collect();
            cycle.push(processes[i].role.clone());
            return LaunchError::Cycle { cycle };
        }
        walk.push(i);
        at = deps[i].iter().copied().find(|&j| !placed[j]);
    }
    // Unreachable for a graph that failed Kahn's algorithm; report what we have.
    LaunchError::Cycle {
        cycle: walk.iter().map(|&w| processes[w].role.clone()).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::launch_file::RestartPolicy;
    use mole_types::{GRAPH, Role};
    use proptest::prelude::*;

    fn p(role: &str, deps: &[&str]) -> ProcessSpec {
        ProcessSpec {
            role: role.to_owned(),
            command: format!("mole-{role}"),
            args: Vec::new(),
            env: Default::default(),
            depends_on: deps.iter().map(|d| (*d).to_owned()).collect(),
            restart: RestartPolicy::default(),
        }
    }

    /// The default stack (the world depending on every other role) starts the world last and
    /// the others in file order; it stops in the graph's order, the world first, the monitor last.
    #[test]
    fn default_stack_starts_world_last_and_stops_in_the_graph_order() {
        let others: Vec<&str> = GRAPH
            .iter()
            .map(|r| r.role.name())
            .filter(|r| *r != Role::World.name())
            .collect();
        let mut ps = vec![p(Role::World.name(), &others)];
        ps.extend(others.iter().map(|r| p(r, &[])));
        assert_eq!(start_order(&ps).unwrap(), vec![1, 2, 3, 4, 5, 0]);
        let stopping: Vec<Role> = stop_order(&ps)
            .into_iter()
            .map(|i| ps[i].role.parse().unwrap())
            .collect();
        assert_eq!(stopping, graph::stop_order());
        assert_eq!(stopping.first(), Some(&Role::World));
        assert_eq!(stopping.last(), Some(&Role::Monitor));
    }

    #[test]
    fn chain_is_ordered_and_stable_among_equals() {
        // c needs b, b needs a; d is free and comes first in file order among the ready ones.
        let ps = [p("c", &["b"]), p("d", &[]), p("b", &["a"]), p("a", &[])];
        assert_eq!(start_order(&ps).unwrap(), vec![1, 3, 2, 0]);
    }

    #[test]
    fn cycle_is_named() {
        let ps = [
            p("free", &[]),
            p("a", &["b"]),
            p("b", &["c"]),
            p("c", &["a"]),
        ];
        let e = start_order(&ps).unwrap_err();
        match &e {
            LaunchError::Cycle { cycle } => {
                assert_eq!(cycle, &["a", "b", "c", "a"]);
            }
            other => panic!("expected a cycle, got {other:?}"),
        }
        assert_eq!(
            e.to_string(),
            "dependency cycle: a -> b -> c -> a (each depends on the next)"
        );
        assert_eq!(e.exit_code(), 2);
    }

    #[test]
    fn self_dependency_is_a_cycle() {
        let e = start_order(&[p("a", &["a"])]).unwrap_err();
        assert!(matches!(e, LaunchError::Cycle { ref cycle } if cycle == &["a", "a"]));
    }

    #[test]
    fn unknown_dependency_and_duplicate_role() {
        let e = start_order(&[p("a", &["ghost"])]).unwrap_err();
        assert!(e.to_string().contains("`ghost`"), "{e}");
        let e = start_order(&[p("a", &[]), p("a", &[])]).unwrap_err();
        assert!(matches!(e, LaunchError::DuplicateRole { .. }));
    }

    #[test]
    fn empty_stack_has_empty_order() {
        assert!(start_order(&[]).unwrap().is_empty());
    }

    proptest! {
        /// Acyclic by construction (edges only to earlier indices, then shuffled by reversing):
        /// the order is a permutation and every dependency comes first.
        #[test]
        fn order_respects_every_dependency(edges in proptest::collection::vec(
            proptest::collection::vec(any::<prop::sample::Index>(), 0..4), 1..12)) {
            let n = edges.len();
            let names: Vec<String> = (0..n).map(|i| format!("r{i}")).collect();
            let mut ps: Vec<ProcessSpec> = (0..n).map(|i| {
                let deps: Vec<String> = if i == 0 { Vec::new() } else {
                    edges[i].iter().map(|ix| names[ix.index(i)].clone()).collect()
                };
                let mut s = p(&names[i], &[]);
                s.depends_on = deps;
                s
            }).collect();
            ps.reverse();
            let order = start_order(&ps).unwrap();
            let mut seen = order.clone();
            seen.sort_unstable();
            prop_assert_eq!(seen, (0..n).collect::<Vec<_>>());
            let pos = |role: &str| order.iter().position(|&i| ps[i].role == role).unwrap();
            for q in &ps {
                for d in &q.depends_on {
                    prop_assert!(pos(d) < pos(&q.role));
                }
            }
        }
    }
}
