//! mole's bridge between machines: chosen topics of a namespace carried between iceoryx2 (shared
//! memory, one machine) and zenoh (the network), in both directions.
//!
//! This library is what the bridge decides, without IPC or network: which topics cross under
//! which zenoh key ([`spec`]), with which delivery in each clock mode ([`delivery`]), and what
//! becomes of a sample that comes from the peer ([`inbound`]). The main (`src/main.rs`) wires it
//! to a mole [`Context`](mole_runtime::Context) and a zenoh session.

pub mod delivery;
pub mod inbound;
pub mod spec;

pub use delivery::{Delivery, delivery};
pub use inbound::{Forward, Forwarding, descriptor};
pub use spec::{BridgeSpec, Tls, key_expr};
