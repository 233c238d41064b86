//! The link between two bridges: who is on it, and whether it is the peer this bridge expects.
//!
//! Each bridge holds a liveliness token `mole/<namespace>/bridge/<peer namespace>`: its own
//! namespace and the one it expects on the other side. The link is up when the token of the
//! expected peer is there, that is the bridge of `peer_namespace` that expects this namespace in
//! turn; any other bridge's token is a stranger, reported with both namespaces, so two halves
//! started with namespaces that do not match say so instead of waiting for each other.
//!
//! [`Link`] is that watch on a zenoh session: the bridges' liveliness tokens, this bridge's own
//! among them.

use crate::{BridgeSpec, Failed, key_expr};
use mole_runtime::{BadInput, Context, Ringer};
use mole_types::graph::nodes::BRIDGE;
use mole_types::link::PEER_TIMEOUT;
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait;
use zenoh::sample::SampleKind;

/// One bridge on the link: its namespace and the namespace it expects its peer in.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct LinkToken {
    pub namespace: String,
    pub peer: String,
}

impl LinkToken {
    /// Its liveliness token's key: `mole/<namespace>/bridge/<peer>`.
    #[must_use]
    pub fn key(&self) -> String {
        key_expr(&self.namespace, &format!("{BRIDGE}/{}", self.peer))
    }

    /// The token of the key `key`, if it is a bridge's.
    #[must_use]
    pub fn parse(key: &str) -> Option<LinkToken> {
        let (head, peer) = key.split_once(&format!("/{BRIDGE}/"))?;
        let (_, namespace) = head.split_once('/')?;
        let token = LinkToken {
            namespace: namespace.to_owned(),
            peer: peer.to_owned(),
        };
        (!namespace.is_empty() && !peer.is_empty() && token.key() == key).then_some(token)
    }
}

impl core::fmt::Display for LinkToken {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "namespace `{}` with peer_namespace `{}`",
            self.namespace, self.peer
        )
    }
}

/// The key expression of every bridge's token, whatever its namespaces.
#[must_use]
pub fn every_link_token() -> String {
    key_expr("**", &format!("{BRIDGE}/**"))
}

/// What a token's coming or going changed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LinkChange {
    /// The expected peer is there (again).
    Up,
    /// The expected peer is gone; `losses` counts how often.
    Down { losses: u64 },
    /// A bridge that is not the expected peer is on the link.
    Stranger(LinkToken),
    /// Nothing worth saying (this bridge's own token, a stranger gone, a repeat).
    Nothing,
}

/// What a bridge sees of the bridges on the link.
#[derive(Debug, Clone)]
pub struct LinkWatch {
    me: LinkToken,
    /// Every other bridge seen on the link, and whether it is there now: one that left before
    /// this bridge gave up (it gave up first) is still what this bridge saw.
    strangers: BTreeMap<LinkToken, bool>,
    up: bool,
    /// The peer came (back) since [`LinkWatch::came_back`] was last asked.
    arrived: bool,
    losses: u64,
}

impl LinkWatch {
    /// The watch of the bridge of `namespace` whose peer is in `peer`.
    #[must_use]
    pub fn new(namespace: &str, peer: &str) -> LinkWatch {
        LinkWatch {
            me: LinkToken {
                namespace: namespace.to_owned(),
                peer: peer.to_owned(),
            },
            strangers: BTreeMap::new(),
            up: false,
            arrived: false,
            losses: 0,
        }
    }

    /// This bridge's own token.
    #[must_use]
    pub fn own(&self) -> &LinkToken {
        &self.me
    }

    /// The token the peer holds: its namespace, expecting this one.
    #[must_use]
    pub fn expected(&self) -> LinkToken {
        LinkToken {
            namespace: self.me.peer.clone(),
            peer: self.me.namespace.clone(),
        }
    }

    /// A token of `key` appeared (`alive`) or went.
    pub fn saw(&mut self, key: &str, alive: bool) -> LinkChange {
        let Some(token) = LinkToken::parse(key) else {
            return LinkChange::Nothing;
        };
        if token == self.me {
            return LinkChange::Nothing;
        }
        if token == self.expected() {
            return match (alive, self.up) {
                (true, false) => {
                    self.up = true;
                    self.arrived = true;
                    LinkChange::Up
                }
                (false, true) => {
                    self.up = false;
                    self.losses += 1;
                    LinkChange::Down {
                        losses: self.losses,
                    }
                }
                _ => LinkChange::Nothing,
            };
        }
        let was_there = self.strangers.insert(token.clone(), alive);
        if alive && was_there != Some(true) {
            return LinkChange::Stranger(token);
        }
        LinkChange::Nothing
    }

    /// Whether the expected peer is there.
    #[must_use]
    pub fn is_up(&self) -> bool {
        self.up
    }

    /// Whether the peer came (back) since the last call.
    pub fn came_back(&mut self) -> bool {
        std::mem::take(&mut self.arrived)
    }

    /// What a bridge says of a stranger when it comes: both bridges' namespaces.
    #[must_use]
    pub fn stranger_warning(&self, stranger: &LinkToken) -> String {
        format!(
            "another bridge on the link: {stranger}; this bridge is {} and waits for {}",
            self.me,
            self.expected()
        )
    }

    /// Why a bridge gives up when its peer did not come within [`PEER_TIMEOUT`]: what it saw on
    /// the link (the strangers, there or gone, or nobody; `endpoints` says where it looked) and what it
    /// expected.
    #[must_use]
    pub fn gave_up(&self, endpoints: &str) -> String {
        let seen = if self.strangers.is_empty() {
            format!("no bridge on the link ({endpoints})")
        } else {
            let strangers: Vec<String> = self
                .strangers
                .iter()
                .map(|(stranger, there)| {
                    let tense = if *there { "is" } else { "was" };
                    format!("on the link {tense} the bridge of {stranger}")
                })
                .collect();
            strangers.join(", and ")
        };
        format!(
            "the peer's bridge did not come within {PEER_TIMEOUT:?}: {seen}; this half is {} \
             and expects the bridge of {}: expected each half's bridge.peer_namespace to be the \
             other's --namespace, both started within {PEER_TIMEOUT:?}",
            self.me,
            self.expected()
        )
    }
}

/// The bridges' liveliness tokens, watched ([`LinkWatch`]): the peer's arrivals and departures
/// are reported, and any other bridge on the link with both namespaces.
pub struct Link {
    state: Arc<Mutex<LinkWatch>>,
    _watch: zenoh::pubsub::Subscriber<()>,
}

impl Link {
    /// Watches every bridge's token on `session`; each change rings `ringer`.
    pub fn watch(
        session: &zenoh::Session,
        spec: &BridgeSpec,
        ringer: &Ringer,
    ) -> Result<Link, Failed> {
        let state = Arc::new(Mutex::new(LinkWatch::new(
            &spec.namespace,
            &spec.peer_namespace,
        )));
        let (seen, ringer, peer) = (state.clone(), ringer.clone(), spec.peer_namespace.clone());
        let watch = session
            .liveliness()
            .declare_subscriber(every_link_token())
            .history(true)
            .callback(move |sample| {
                let mut state = seen.lock().unwrap_or_else(|e| e.into_inner());
                let alive = sample.kind() == SampleKind::Put;
                match state.saw(sample.key_expr().as_str(), alive) {
                    LinkChange::Up => tracing::info!(peer, "link up: the peer's bridge is there"),
                    LinkChange::Down { losses } => tracing::warn!(
                        peer,
                        losses,
                        "link down: the peer's bridge is gone; its topics stop here until it is back"
                    ),
                    LinkChange::Stranger(stranger) => {
                        tracing::warn!("{}", state.stranger_warning(&stranger));
                    }
                    LinkChange::Nothing => {}
                }
                drop(state);
                ringer.ring();
            })
            .wait()?;
        Ok(Link {
            state,
            _watch: watch,
        })
    }

    fn state(&self) -> std::sync::MutexGuard<'_, LinkWatch> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// This bridge's own token's key.
    #[must_use]
    pub fn own_key(&self) -> String {
        self.state().own().key()
    }

    /// Declares this bridge's own token on `session`: the peer sees it while it lives.
    pub fn declare_token(
        &self,
        session: &zenoh::Session,
    ) -> Result<zenoh::liveliness::LivelinessToken, Failed> {
        session.liveliness().declare_token(self.own_key()).wait()
    }

    /// Says what it waits for, then waits until the peer's bridge is there; false on a
    /// shutdown, an error (the launch files' namespaces or endpoints do not meet: exit 2) saying
    /// what is on the link if the peer is not there within [`PEER_TIMEOUT`].
    pub fn wait_for_peer(&self, ctx: &Context, spec: &BridgeSpec) -> Result<bool, BadInput> {
        tracing::info!(
            peer = %spec.peer_namespace,
            listen = ?spec.listen.iter().map(|e| e.as_str()).collect::<Vec<_>>(),
            connect = ?spec.connect.iter().map(|e| e.as_str()).collect::<Vec<_>>(),
            out = ?spec.out, inbound = ?spec.inbound,
            "waiting for the peer's bridge"
        );
        let started = Instant::now();
        let mut said = Instant::now();
        while !self.state().is_up() {
            if ctx.shutdown_requested() {
                return Ok(false);
            }
            if started.elapsed() > PEER_TIMEOUT {
                return Err(BadInput(self.state().gave_up(&spec.whereabouts())));
            }
            if said.elapsed() > Duration::from_secs(5) {
                tracing::info!("still waiting for the peer's bridge");
                said = Instant::now();
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        self.came_back();
        Ok(true)
    }

    /// Whether the peer came back since the last call.
    pub fn came_back(&self) -> bool {
        self.state().came_back()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_token_names_both_namespaces() {
        let token = LinkToken {
            namespace: "onboard".into(),
            peer: "offboard".into(),
        };
        assert_eq!(token.key(), "mole/onboard/bridge/offboard");
        assert_eq!(LinkToken::parse(&token.key()), Some(token));
        assert_eq!(LinkToken::parse("mole/onboard/sensing/scan"), None);
        assert_eq!(LinkToken::parse("mole/onboard/bridge"), None);
        assert_eq!(every_link_token(), "mole/**/bridge/**");
    }

    #[test]
    fn the_link_is_up_only_with_the_peer_that_expects_this_side() {
        let mut watch = LinkWatch::new("onboard", "offboard");
        assert_eq!(
            watch.saw("mole/onboard/bridge/offboard", true),
            LinkChange::Nothing
        );
        // The off-board half started with another namespace, expecting this one.
        let wrong = "mole/offboard2/bridge/onboard";
        assert_eq!(
            watch.saw(wrong, true),
            LinkChange::Stranger(LinkToken {
                namespace: "offboard2".into(),
                peer: "onboard".into()
            })
        );
        assert_eq!(watch.saw(wrong, true), LinkChange::Nothing, "said once");
        // The right namespace, expecting another half.
        assert!(matches!(
            watch.saw("mole/offboard/bridge/onboard2", true),
            LinkChange::Stranger(_)
        ));
        assert!(!watch.is_up());
        let why = watch.gave_up("listening on tcp/127.0.0.1:7447");
        for needle in [
            "namespace `offboard2` with peer_namespace `onboard`",
            "namespace `offboard` with peer_namespace `onboard2`",
            "this half is namespace `onboard` with peer_namespace `offboard`",
            "expects the bridge of namespace `offboard` with peer_namespace `onboard`",
        ] {
            assert!(why.contains(needle), "no `{needle}` in: {why}");
        }

        assert_eq!(
            watch.saw("mole/offboard/bridge/onboard", true),
            LinkChange::Up
        );
        assert!(watch.is_up() && watch.came_back() && !watch.came_back());
        assert_eq!(
            watch.saw("mole/offboard/bridge/onboard", false),
            LinkChange::Down { losses: 1 }
        );
        assert_eq!(
            watch.saw("mole/offboard/bridge/onboard", true),
            LinkChange::Up
        );
    }

    #[test]
    fn nobody_on_the_link_is_said_with_where_the_bridge_looked() {
        let watch = LinkWatch::new("a", "b");
        let why = watch.gave_up("connecting to tcp/10.0.0.2:7447");
        assert!(
            why.contains("no bridge on the link (connecting to tcp/10.0.0.2:7447)"),
            "{why}"
        );
    }

    /// The other half's bridge gave up first and left: it is still what this one saw.
    #[test]
    fn a_stranger_that_left_is_said_as_seen() {
        let mut watch = LinkWatch::new("a", "b");
        let stranger = "mole/c/bridge/a";
        assert!(matches!(watch.saw(stranger, true), LinkChange::Stranger(_)));
        assert_eq!(watch.saw(stranger, false), LinkChange::Nothing);
        let why = watch.gave_up("connecting to tcp/10.0.0.2:7447");
        assert!(
            why.contains("on the link was the bridge of namespace `c` with peer_namespace `a`"),
            "{why}"
        );
        assert!(
            matches!(watch.saw(stranger, true), LinkChange::Stranger(_)),
            "back"
        );
    }
}
