//! mole's bridge between machines: chosen topics of a namespace carried between iceoryx2 (shared
//! memory, one machine) and zenoh (the network), in both directions.
//!
//! This library is what the bridge decides, without IPC or network: which topics cross under
//! which zenoh key ([`spec`]), with which delivery in each clock mode ([`delivery`]), how
//! samples from the peer wait for the bridge's thread ([`inbox`]), and what becomes of each
//! ([`inbound`]). The main (`src/main.rs`) wires it
//! to a mole [`Context`](mole_runtime::Context) and a zenoh session.

pub mod delivery;
pub mod inbound;
pub mod inbox;
pub mod spec;

pub use delivery::{Delivery, delivery};
pub use inbound::{Forward, Forwarding, descriptor};
pub use inbox::{Entry, INBOX_CAPACITY, Inbox};
pub use spec::{BridgeSpec, Tls, key_expr};
