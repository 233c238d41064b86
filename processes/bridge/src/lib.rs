//! mole's bridge between machines: chosen topics of a namespace carried between iceoryx2 (shared
//! memory, one machine) and zenoh (the network), in both directions.
//!
//! This library is what the bridge decides, without IPC or network: which topics cross under
//! which zenoh key ([`spec`]), with which delivery in each clock mode ([`delivery`]), in which
//! order this host's samples leave ([`outbound`]), whether the bridge on the other side is the
//! expected peer ([`link`]), how samples from the peer wait for the bridge's thread
//! ([`inbox`]), and what becomes of each ([`inbound`]). The main
//! (`src/main.rs`) wires it to a mole [`Context`](mole_runtime::Context) and a zenoh session.

pub mod delivery;
pub mod inbound;
pub mod inbox;
pub mod link;
pub mod outbound;
pub mod spec;

pub use delivery::{Delivery, delivery};
pub use inbound::{Forward, Forwarding, descriptor};
pub use inbox::{Entry, INBOX_CAPACITY, Inbox};
pub use link::{LinkChange, LinkToken, LinkWatch, every_link_token};
pub use outbound::{Outbound, Staged, send_in_order};
pub use spec::{BridgeSpec, LISTENING, Tls, key_expr};
