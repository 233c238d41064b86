//! mole's bridge between machines: chosen topics of a namespace carried between iceoryx2 (shared
//! memory, one machine) and zenoh (the network), in both directions.
//!
//! What the bridge decides is here and tested without IPC or network: which topics cross under
//! which zenoh key ([`spec`]), with which delivery in each clock mode ([`delivery`]), in which
//! order this host's samples leave ([`outbound`]), whether the bridge on the other side is the
//! expected peer ([`link`]), how samples from the peer wait for the bridge's thread
//! ([`inbox`]), and what becomes of each ([`inbound`]). It also holds what wires these to a mole
//! [`Context`](mole_runtime::Context) and a zenoh session, for the main (`src/main.rs`): the
//! session ([`session`]), the topics out ([`Outs`]) and in ([`Ins`]), the link's watch
//! ([`Link`]); and the zenoh benchmark of `mole bench ipc` ([`zenoh_bench`]).

pub mod delivery;
pub mod inbound;
pub mod inbox;
pub mod link;
pub mod outbound;
pub mod session;
pub mod spec;
pub mod zenoh_bench;

pub use delivery::{Delivery, delivery, qos};
pub use inbound::{Forward, Forwarding, Ins, PeerInbox, descriptor};
pub use inbox::{Entry, INBOX_CAPACITY, Inbox};
pub use link::{Link, LinkChange, LinkToken, LinkWatch, every_link_token};
pub use outbound::{Outbound, Outs, Staged, send_in_order};
pub use session::{listen_again, open_session};
pub use spec::{BridgeSpec, LISTENING, Tls, key_expr, spec_of};

/// Why the bridge stopped (zenoh's errors are `Send + Sync`, so all are).
pub type Failed = Box<dyn std::error::Error + Send + Sync>;

/// The bridge's role (node `mole/<ns>/bridge`, log `bridge.log`).
pub const ROLE: &str = mole_types::graph::nodes::BRIDGE;
