//! `mole eval --check` on a slice of the baseline's own worlds: lockstep runs are repeatable, so
//! a world the baseline holds is compared with itself, world by world, instead of a few worlds'
//! mean with many worlds' interval (which a slice's chance draw of hard worlds would fail).

use super::metrics::{Aggregate, Direction, Kind, WorldMetrics, better};
use std::collections::BTreeMap;

/// Whether `now` is a slice of `baseline`: fewer worlds, each of them one the baseline ran
/// (same name, same seed, same limit).
pub fn is_slice(baseline: &[WorldMetrics], now: &[WorldMetrics]) -> bool {
    !now.is_empty()
        && now.len() < baseline.len()
        && now.iter().all(|w| same_world(baseline, w).is_some())
}

fn same_world<'a>(baseline: &'a [WorldMetrics], w: &WorldMetrics) -> Option<&'a WorldMetrics> {
    baseline
        .iter()
        .find(|b| b.world == w.world && b.seed == w.seed && b.ticks_limit == w.ticks_limit)
}

/// Each judged metric of each world of `now` that is worse than the same world's in `baseline`:
/// a yes/no that turned to no (a count that rose from 0 is a yes/no too), a quantity worse by
/// more than the half-width of the baseline suite's 95% interval, a value that vanished.
pub fn world_regressions(
    baseline: &[WorldMetrics],
    aggregates: &BTreeMap<String, Aggregate>,
    now: &[WorldMetrics],
) -> Vec<String> {
    let mut out = Vec::new();
    for w in now {
        let Some(b) = same_world(baseline, w) else {
            continue;
        };
        for ((metric, was, kind), (_, is, _)) in b.values().into_iter().zip(w.values()) {
            let (Some(direction), Some(was)) = (better(metric), was) else {
                continue;
            };
            let Some(is) = is else {
                out.push(format!(
                    "{}: {metric} was {was:.4} in the baseline, now it has no value",
                    w.world
                ));
                continue;
            };
            let tolerance = match kind {
                Kind::Fraction => 0.0,
                Kind::Mean => aggregates
                    .get(metric)
                    .map_or(0.0, |a| 0.5 * (a.ci95[1] - a.ci95[0])),
            };
            let worse = match direction {
                Direction::Higher => is < was - tolerance,
                Direction::Lower => is > was + tolerance,
            };
            if worse {
                out.push(format!(
                    "{}: {metric} {is:.4} now, {was:.4} in the baseline (tolerance {tolerance:.4})",
                    w.world
                ));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::metrics::aggregate;

    fn world(i: u64, success: bool, rmse: f64) -> WorldMetrics {
        WorldMetrics {
            world: format!("clutter-{i:04}"),
            seed: i,
            ticks_limit: 1000,
            success: Some(success),
            localization_rmse_m: Some(rmse),
            contact_events: Some(0),
            ..WorldMetrics::default()
        }
    }

    /// A slice is fewer worlds, each the baseline's own; a different seed or limit is not.
    #[test]
    fn a_slice_is_some_of_the_baselines_own_worlds() {
        let base: Vec<_> = (0..5).map(|i| world(i, true, 0.02)).collect();
        assert!(is_slice(&base, &base[..2]));
        assert!(!is_slice(&base, &base), "every world is the suite itself");
        assert!(!is_slice(&base, &[]));
        let mut other = base[1].clone();
        other.ticks_limit = 2000;
        assert!(!is_slice(&base, &[base[0].clone(), other]));
        assert!(!is_slice(&base, &[world(9, true, 0.02)]));
    }

    /// The same worlds with the same values pass; a lost success, a new contact, an RMSE worse
    /// than the suite's interval or a vanished value is named with its world; an RMSE worse
    /// within the interval is not.
    #[test]
    fn a_world_worse_than_itself_is_named() {
        let base: Vec<_> = (0..5)
            .map(|i| world(i, true, 0.02 + 0.01 * i as f64))
            .collect();
        let aggregates = aggregate(&base);
        let half = 0.5
            * (aggregates["localization_rmse_m"].ci95[1]
                - aggregates["localization_rmse_m"].ci95[0]);
        assert!(world_regressions(&base, &aggregates, &base[..2]).is_empty());
        let mut now = base[..3].to_vec();
        now[0].success = Some(false);
        now[1].contact_events = Some(1);
        now[2].localization_rmse_m = Some(0.04 + 0.5 * half);
        let found = world_regressions(&base, &aggregates, &now);
        assert_eq!(found.len(), 2, "{found:?}");
        assert!(
            found[0].starts_with("clutter-0000: success 0.0000 now"),
            "{found:?}"
        );
        assert!(
            found[1].starts_with("clutter-0001: contact_events 1.0000 now"),
            "{found:?}"
        );
        now[2].localization_rmse_m = Some(0.04 + 1.5 * half);
        let found = world_regressions(&base, &aggregates, &now);
        assert!(
            found[2].starts_with("clutter-0002: localization_rmse_m"),
            "{found:?}"
        );
        let mut gone = base[..1].to_vec();
        gone[0].localization_rmse_m = None;
        let found = world_regressions(&base, &aggregates, &gone);
        assert_eq!(
            found,
            ["clutter-0000: localization_rmse_m was 0.0200 in the baseline, now it has no value"]
        );
    }
}
