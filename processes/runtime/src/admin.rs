//! Node administration: creating a process's node, cleaning what dead nodes left, listing the
//! live nodes and the topics of a namespace.

use crate::error::RuntimeError;
use crate::time::set_iceoryx_log_level;
use iceoryx2::node::{DeadNodeView, NodeCleanupFailure, NodeView};
use iceoryx2::prelude::*;
use std::collections::{BTreeMap, HashSet};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The node `mole/<namespace>/<role>`, iceoryx2's signal handling disabled, and its sweep of
/// every dead node when a node is created or dropped too: a process killed during that sweep, or
/// whose sweep fails (iceoryx2 then holds the dead node's cleaner lock until the process ends),
/// would block the node's cleaning. The launcher sweeps instead ([`cleanup_dead_nodes`]).
pub(crate) fn create_node(namespace: &str, role: &str) -> Result<Node<ipc::Service>, RuntimeError> {
    set_iceoryx_log_level();
    let node_name = format!("mole/{namespace}/{role}");
    let name: NodeName = node_name
        .as_str()
        .try_into()
        .map_err(|e| RuntimeError::Name(node_name.clone(), format!("{e:?}")))?;
    let mut config = Config::global_config().clone();
    config.global.node.cleanup_dead_nodes_on_creation = false;
    config.global.node.cleanup_dead_nodes_on_destruction = false;
    NodeBuilder::new()
        .name(&name)
        .config(&config)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| RuntimeError::Node(node_name, format!("{e:?}")))
}

/// How long an iceoryx2 record (a node's files, a service's static config, a listener's event)
/// may stay half-made before its maker counts as dead. iceoryx2 makes and seals each within
/// milliseconds, so one still half-made after this long was left by a process killed making it.
pub const HALF_MADE_AGE: Duration = Duration::from_secs(5);

/// Where Linux keeps POSIX shared memory, iceoryx2's segments among it.
const SHARED_MEMORY_DIR: &str = "/dev/shm";

/// Removes the resources of every dead node (a crashed earlier run, a killed process), so they
/// never block a new one, and what a process killed while making a node, a service or a
/// listener left, which iceoryx2 does not see. Returns how many of both were cleaned.
pub fn cleanup_dead_nodes() -> usize {
    let config = Config::global_config();
    let nodes_dir = std_path(&config.global.node_dir());
    // First, so that iceoryx2 finds a half-made service segment gone, not unreadable.
    let half_made_segments = remove_half_made_shared_memory(config);
    let mut listed = HashSet::new();
    let mut dead = Vec::new();
    let result = Node::<ipc::Service>::list(config, |state| {
        listed.insert(state.node_id().value());
        if let NodeState::Dead(view) = state {
            dead.push(view);
        }
        CallbackProgression::Continue
    });
    if let Err(e) = result {
        tracing::warn!("cannot list nodes: {e:?}");
        return 0;
    }
    let dead_ids: HashSet<u128> = dead.iter().map(|view| view.id().value()).collect();
    let mut cleaned = 0;
    let mut failed = 0;
    for view in dead {
        let name = view.details().as_ref().map(|d| d.name().to_string());
        match remove_dead_node(view, config) {
            Ok(true) => {
                cleaned += 1;
                tracing::info!(node = ?name, "cleaned the resources of a dead node");
            }
            Ok(false) => tracing::debug!(node = ?name, "another process cleans a dead node"),
            Err(e) => {
                failed += 1;
                tracing::debug!(node = ?name, "cannot clean a dead node: {e:?}");
            }
        }
    }
    let half_made = half_made_segments
        + remove_half_made_nodes(&nodes_dir, &config.global.prefix, &listed)
        + remove_half_made_services(config)
        + remove_orphaned_services(config)
        + remove_orphaned_port_segments(config)
        + remove_dead_doorbells(config, &listed, &dead_ids);
    if half_made > 0 {
        tracing::info!(
            half_made,
            "removed what processes killed while making a node, a service or a listener left"
        );
    }
    if failed > 0 {
        tracing::warn!(
            failed,
            "dead nodes whose resources iceoryx2 could not clean (RUST_LOG=debug names them)"
        );
    }
    cleaned + half_made
}

/// Cleans one dead node; `Ok(false)` when another process did or is doing it. A file its process
/// never sealed (iceoryx2 seals each by making it read-only) is one it was killed while writing:
/// iceoryx2 seals a service or port tag before it uses the service or makes the port, so such a
/// tag stands for nothing, but iceoryx2 does not see it and so cannot remove the node's directory.
fn remove_dead_node(
    view: DeadNodeView<ipc::Service>,
    config: &Config,
) -> Result<bool, NodeCleanupFailure> {
    let id = view.id().value();
    let nodes_dir = std_path(&config.global.node_dir());
    let node_dir = nodes_dir.join(id.to_string());
    for file in entries(&node_dir) {
        if is_unsealed(&file) {
            remove(&file);
        }
    }
    match view.try_remove_stale_resources() {
        Ok(()) => Ok(true),
        Err(NodeCleanupFailure::ResourcesAlreadyCleanedUp) => Ok(false),
        // A cleaner removes the node's directory before its monitor; a monitor left on its own
        // for long is one whose cleaner was killed in between, and iceoryx2 waits for it forever.
        Err(NodeCleanupFailure::AnotherInstanceIsCleaningUpTheNode) => {
            let monitor = monitor_files(&nodes_dir, &config.global.prefix, id);
            if node_dir.exists() || !all_older_than(&monitor, HALF_MADE_AGE) {
                return Ok(false);
            }
            monitor.iter().for_each(|f| remove(f));
            Ok(true)
        }
        Err(e) => Err(e),
    }
}

/// Removes iceoryx2's shared-memory segments (a service's dynamic config, a port's data, a
/// listener's event) that their creator never finished, once old enough. iceoryx2 makes a
/// segment write-only, initialises it and only then lets its owner read it; nobody can open one
/// before, so a segment still write-only after this long is only in the way: iceoryx2 cannot open
/// it to clean it, and a service whose dynamic config it is can be neither opened nor removed.
/// Returns how many were removed.
fn remove_half_made_shared_memory(config: &Config) -> usize {
    use std::os::unix::fs::PermissionsExt;
    let prefix = String::from_utf8_lossy(config.global.prefix.as_bytes()).into_owned();
    let half_made: Vec<PathBuf> = entries(Path::new(SHARED_MEMORY_DIR))
        .into_iter()
        .filter(|path| {
            path.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with(&prefix))
                && std::fs::symlink_metadata(path)
                    .is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o400 == 0)
                && all_older_than(std::slice::from_ref(path), HALF_MADE_AGE)
        })
        .collect();
    half_made.iter().for_each(|p| remove(p));
    half_made.len()
}

/// Removes the shared memory named after ports that no node has any more, once old enough: a
/// listener's event (`.event…`), a publisher's data segment, a publisher–subscriber connection. A port's tag
/// is made before any of these, and iceoryx2 removes them when it removes the port from its
/// service, so it leaves those of a port killed after making them but before joining the
/// service, and a connection one side made to a peer whose cleaning had already passed it.
/// Returns how many were removed.
fn remove_orphaned_port_segments(config: &Config) -> usize {
    let prefix = &config.global.prefix;
    let ports: HashSet<u128> = entries(&std_path(&config.global.node_dir()))
        .iter()
        .flat_map(|node| entries(node))
        .filter_map(|tag| record_id(&tag, prefix, &config.global.node.port_tag_suffix))
        .collect();
    let prefix = String::from_utf8_lossy(prefix.as_bytes()).into_owned();
    let service = &config.global.service;
    let suffixes: Vec<String> = [
        &service.event_connection_suffix,
        &service.connection_suffix,
        &service.data_segment_suffix,
    ]
    .iter()
    .map(|s| String::from_utf8_lossy(s.as_bytes()).into_owned())
    .collect();
    let orphans: Vec<PathBuf> = entries(Path::new(SHARED_MEMORY_DIR))
        .into_iter()
        .filter(|path| {
            let port_ids = path
                .file_name()
                .and_then(|n| n.to_str())
                .filter(|n| n.starts_with(&prefix))
                .and_then(|n| suffixes.iter().find_map(|s| n.split_once(s.as_str())))
                .map(|(name, _)| name)
                .map(segment_port_ids)
                .unwrap_or_default();
            !port_ids.is_empty()
                && port_ids.iter().all(|id| !ports.contains(id))
                && all_older_than(std::slice::from_ref(path), HALF_MADE_AGE)
        })
        .collect();
    orphans.iter().for_each(|p| remove(p));
    orphans.len()
}

/// The port ids in a port segment's name `<service hash>_<port id>[_<port id>]`. A port id holds
/// its maker's PID in bits 64..96, so it is above `u64::MAX`; the service hash is hexadecimal and
/// longer than any `u128` in decimal, so it never parses.
fn segment_port_ids(name: &str) -> Vec<u128> {
    name.split('_')
        .skip(1)
        .filter_map(|part| part.parse::<u128>().ok())
        .filter(|id| *id > u128::from(u64::MAX))
        .collect()
}

/// The id in a record's file name `<prefix><id><suffix>`.
fn record_id(file: &Path, prefix: &FileName, suffix: &FileName) -> Option<u128> {
    let name = file.file_name()?.to_str()?;
    let prefix = std::str::from_utf8(prefix.as_bytes()).ok()?;
    let suffix = std::str::from_utf8(suffix.as_bytes()).ok()?;
    name.strip_prefix(prefix)?
        .strip_suffix(suffix)?
        .parse()
        .ok()
}

/// Removes the records (directory and monitor files) of nodes iceoryx2 does not list, which are
/// those killed before their monitor was sealed, once they are old enough that no live process
/// can still be creating them. Returns how many were removed.
fn remove_half_made_nodes(nodes_dir: &Path, prefix: &FileName, listed: &HashSet<u128>) -> usize {
    let prefix = String::from_utf8_lossy(prefix.as_bytes()).into_owned();
    let mut records: BTreeMap<u128, Vec<PathBuf>> = BTreeMap::new();
    for path in entries(nodes_dir) {
        let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
            continue;
        };
        let id = name
            .strip_prefix(&prefix)
            .and_then(|rest| rest.split_once('.'))
            .map_or(name, |(id, _)| id);
        if let Ok(id) = id.parse::<u128>()
            && !listed.contains(&id)
        {
            records.entry(id).or_default().push(path);
        }
    }
    let mut removed = 0;
    for paths in records.values() {
        let mut all: Vec<PathBuf> = paths.clone();
        all.extend(paths.iter().flat_map(|p| entries(p)));
        if all_older_than(&all, HALF_MADE_AGE) {
            paths.iter().for_each(|p| remove(p));
            removed += 1;
        }
    }
    removed
}

/// Removes the static configs of services whose creator was killed before it sealed them, once
/// old enough. iceoryx2 seals a service's static config before it makes anything else of the
/// service, so nothing else exists for it; left in place, it makes every later attempt to open or
/// create the service wait and fail ("hangs in creation"). Returns how many were removed.
fn remove_half_made_services(config: &Config) -> usize {
    let service = &config.global.service;
    let prefix = String::from_utf8_lossy(config.global.prefix.as_bytes()).into_owned();
    let suffix = String::from_utf8_lossy(service.static_config_storage_suffix.as_bytes());
    let half_made: Vec<PathBuf> = entries(&std_path(&config.global.service_dir()))
        .into_iter()
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with(&prefix) && n.ends_with(suffix.as_ref()))
                && is_unsealed(p)
                && all_older_than(std::slice::from_ref(p), HALF_MADE_AGE)
        })
        .collect();
    half_made.iter().for_each(|p| remove(p));
    half_made.len()
}

/// The part of a service's static config that names its dynamic config.
#[derive(serde::Deserialize)]
struct StaticConfig {
    unique_service_id: UniqueServiceId,
}

#[derive(serde::Deserialize)]
struct UniqueServiceId {
    payload_value: u64,
    unique_value: u64,
}

/// The id in the name of the dynamic config of the service whose static config is `text`.
fn dynamic_config_id(text: &str) -> Option<u128> {
    let id = toml::from_str::<StaticConfig>(text).ok()?.unique_service_id;
    Some((u128::from(id.unique_value) << 64) | u128::from(id.payload_value))
}

/// Removes the services that no node uses (no node holds a tag of them), once old enough: their
/// static config and its dynamic config. A node tags a service after creating it, and iceoryx2
/// removes a service when it cleans the last node that tagged it, so it leaves those of a
/// process killed after creating the service but before tagging it. Returns how many were
/// removed.
fn remove_orphaned_services(config: &Config) -> usize {
    let global = &config.global;
    let prefix = String::from_utf8_lossy(global.prefix.as_bytes()).into_owned();
    let tag = String::from_utf8_lossy(global.node.service_tag_suffix.as_bytes()).into_owned();
    let tagged: HashSet<String> = entries(&std_path(&global.node_dir()))
        .iter()
        .flat_map(|node| entries(node))
        .filter_map(|p| {
            let name = p.file_name()?.to_str()?;
            Some(name.strip_prefix(&prefix)?.strip_suffix(&tag)?.to_owned())
        })
        .collect();
    let suffix = String::from_utf8_lossy(global.service.static_config_storage_suffix.as_bytes());
    let dynamic = String::from_utf8_lossy(global.service.dynamic_config_storage_suffix.as_bytes());
    let mut removed = 0;
    for path in entries(&std_path(&global.service_dir())) {
        let Some(hash) = path
            .file_name()
            .and_then(|n| n.to_str())
            .and_then(|n| n.strip_prefix(&prefix)?.strip_suffix(suffix.as_ref()))
        else {
            continue;
        };
        if tagged.contains(hash)
            || is_unsealed(&path)
            || !all_older_than(std::slice::from_ref(&path), HALF_MADE_AGE)
        {
            continue;
        }
        let Some(id) = std::fs::read_to_string(&path)
            .ok()
            .and_then(|text| dynamic_config_id(&text))
        else {
            continue;
        };
        let ending = format!("_{id}{dynamic}");
        entries(Path::new(SHARED_MEMORY_DIR))
            .iter()
            .filter(|p| {
                p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with(&prefix) && n.ends_with(&ending))
            })
            .for_each(|p| remove(p));
        remove(&path);
        removed += 1;
    }
    removed
}

/// Removes the doorbells (`doorbell.rs`) of dead nodes: at once for a node iceoryx2 listed as
/// dead, once old enough for one it does not list (its records are gone, or it is still being
/// made: a node's doorbell is made right after the node). Returns how many were removed.
fn remove_dead_doorbells(config: &Config, listed: &HashSet<u128>, dead: &HashSet<u128>) -> usize {
    let gone: Vec<PathBuf> = entries(&crate::doorbell::doorbell_dir(config))
        .into_iter()
        .filter(|path| {
            let Some(node) = path
                .file_name()
                .and_then(|n| n.to_str())
                .and_then(|n| n.parse::<u128>().ok())
            else {
                return false;
            };
            dead.contains(&node)
                || (!listed.contains(&node)
                    && all_older_than(std::slice::from_ref(path), HALF_MADE_AGE))
        })
        .collect();
    gone.iter().for_each(|p| remove(p));
    gone.len()
}

/// The monitor files (`<prefix><id>.node_monitor…`) of node `id`.
fn monitor_files(nodes_dir: &Path, prefix: &FileName, id: u128) -> Vec<PathBuf> {
    let start = format!("{}{id}.", String::from_utf8_lossy(prefix.as_bytes()));
    entries(nodes_dir)
        .into_iter()
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with(&start))
        })
        .collect()
}

/// The entries of a directory; none when it is not one (or is gone).
fn entries(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .map(|d| d.flatten().map(|e| e.path()).collect())
        .unwrap_or_default()
}

/// Whether a file is still writable by its owner: iceoryx2 creates its records writable and
/// makes them read-only once written.
fn is_unsealed(file: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    std::fs::symlink_metadata(file)
        .is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o200 != 0)
}

/// Whether every path was last changed more than `age` ago (one that vanished meanwhile counts
/// as old: its maker is done with it).
fn all_older_than(paths: &[PathBuf], age: Duration) -> bool {
    paths.iter().all(|p| {
        std::fs::symlink_metadata(p)
            .and_then(|m| m.modified())
            .map_or(true, |t| t.elapsed().is_ok_and(|e| e > age))
    })
}

/// Removes a file or a directory tree; one already gone (another cleaner) is fine, one that
/// cannot be removed (another user's) is said.
fn remove(path: &Path) {
    let result = if path.is_dir() {
        std::fs::remove_dir_all(path)
    } else {
        std::fs::remove_file(path)
    };
    if let Err(e) = result
        && e.kind() != std::io::ErrorKind::NotFound
    {
        tracing::warn!(path = %path.display(), "cannot remove what a dead process left: {e}");
    }
}

/// iceoryx2's path as a standard one.
fn std_path(path: &iceoryx2::prelude::Path) -> PathBuf {
    use std::os::unix::ffi::OsStrExt;
    PathBuf::from(std::ffi::OsStr::from_bytes(path.as_bytes()))
}

/// What iceoryx2 and mole keep on this machine, looked at without changing anything
/// (`mole doctor`).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NodeCensus {
    /// iceoryx2's directory for its records (`/tmp/iceoryx2` by default).
    pub root: PathBuf,
    /// Nodes whose process is alive, by name.
    pub live: Vec<String>,
    /// Nodes whose process is gone but whose resources are still there, by name (or id).
    pub dead: Vec<String>,
    /// Nodes this user may not look at (another user's, made private), by id.
    pub inaccessible: Vec<String>,
    /// Nodes whose records are incomplete or altered, by id.
    pub undefined: Vec<String>,
    /// Doorbells of nodes that no longer exist.
    pub stale_doorbells: usize,
    /// Why iceoryx2 could not list the nodes, if it could not.
    pub unlisted: Option<String>,
}

/// Looks at the nodes and doorbells on this machine; removes nothing (`cleanup_dead_nodes`
/// does).
pub fn node_census() -> NodeCensus {
    let config = Config::global_config();
    let mut census = NodeCensus {
        root: std_path(config.global.root_path()),
        ..NodeCensus::default()
    };
    let mut listed = HashSet::new();
    let name_of = |details: Option<&iceoryx2::node::NodeDetails>, id: u128| {
        details.map_or_else(|| format!("node {id}"), |d| d.name().to_string())
    };
    let result = Node::<ipc::Service>::list(config, |state| {
        let id = state.node_id().value();
        listed.insert(id);
        match state {
            NodeState::Alive(view) => census.live.push(name_of(view.details().as_ref(), id)),
            NodeState::Dead(view) => census.dead.push(name_of(view.details().as_ref(), id)),
            NodeState::Inaccessible(_) => census.inaccessible.push(format!("node {id}")),
            NodeState::Undefined(_) => census.undefined.push(format!("node {id}")),
        }
        CallbackProgression::Continue
    });
    census.unlisted = result.err().map(|e| format!("{e:?}"));
    census.stale_doorbells = entries(&crate::doorbell::doorbell_dir(config))
        .into_iter()
        .filter(|path| {
            path.file_name()
                .and_then(|n| n.to_str())
                .and_then(|n| n.parse::<u128>().ok())
                .is_some_and(|node| {
                    !listed.contains(&node)
                        && all_older_than(std::slice::from_ref(path), HALF_MADE_AGE)
                })
        })
        .count();
    census.live.sort();
    census.dead.sort();
    census
}

/// Names of the live nodes of a namespace (`mole/<ns>/<role>`), e.g. to refuse a second stack.
pub fn live_nodes_in_namespace(namespace: &str) -> Vec<String> {
    let prefix = format!("mole/{namespace}/");
    let mut names = Vec::new();
    let _ = Node::<ipc::Service>::list(Config::global_config(), |state| {
        if let NodeState::Alive(view) = state
            && let Some(details) = view.details()
        {
            let name = details.name().to_string();
            if name.starts_with(&prefix) {
                names.push(name);
            }
        }
        CallbackProgression::Continue
    });
    names
}

/// The publish-subscribe services of a namespace as iceoryx2 lists them: `(topic, payload type
/// name)`, sorted. Any tool that lists iceoryx2 services (`iox2 service list`) sees the same.
pub fn list_topics(namespace: &str) -> Vec<(String, String)> {
    use iceoryx2::service::Service as _;
    use iceoryx2::service::static_config::messaging_pattern::MessagingPattern;
    let prefix = format!("mole/{namespace}/");
    let mut topics = Vec::new();
    let result = ipc::Service::list(Config::global_config(), |details| {
        let name = details.static_details.name().as_str();
        if let Some(topic) = name.strip_prefix(&prefix)
            && let MessagingPattern::PublishSubscribe(config) =
                details.static_details.messaging_pattern()
        {
            let payload = config
                .message_type_details()
                .payload
                .type_name()
                .to_string();
            topics.push((topic.to_string(), payload));
        }
        CallbackProgression::Continue
    });
    if let Err(e) = result {
        tracing::warn!("cannot list services: {e:?}");
    }
    topics.sort();
    topics
}

#[cfg(test)]
mod tests {
    use super::{dynamic_config_id, segment_port_ids};

    /// A service's static config (as iceoryx2 0.10 writes it) names its dynamic config: the
    /// one a killed creator left beside it in a CI run.
    #[test]
    fn the_dynamic_config_is_found_from_the_static_one() {
        let text = "service_hash = \"15371ab1d2fb57328b41846c542104409503b822\"\n\
                    service_name = \"mole/t/planning/status\"\nattributes = []\n\n\
                    [unique_service_id]\npayload_value = 2228098028072363687\n\
                    unique_value = 68719504931\n";
        assert_eq!(
            dynamic_config_id(text),
            Some(1267651120336406657765583382183)
        );
        assert_eq!(dynamic_config_id("not a static config"), None);
    }

    #[test]
    fn port_ids_are_read_from_segment_names_and_the_service_hash_is_not_one() {
        let hash = "iox2_b9fc73e5c1f646968758453273c6c65cb372831b";
        assert_eq!(
            segment_port_ids(&format!(
                "{hash}_158456514828278524616091127272_1901476090252985756089558519272"
            )),
            vec![
                158456514828278524616091127272,
                1901476090252985756089558519272
            ]
        );
        assert!(segment_port_ids(&format!("{hash}_42")).is_empty());
        // A hash of decimal digits only is still longer than any u128.
        let digits = "iox2_1234567890123456789012345678901234567890";
        assert!(segment_port_ids(digits).is_empty());
        assert!(segment_port_ids("iox2_9204dd183d1c4d8e_node.0_10_0").is_empty());
    }
}
