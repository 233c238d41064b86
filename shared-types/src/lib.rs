//! Every message mole's processes exchange, with its topic, its validation and its layout.
//!
//! The rules (docs/architecture.md, "Messages"): `#[repr(C)]`, an explicit versioned `type_name`, only
//! fixed-size integers, floats and arrays of them, explicit `_pad` fields, sizes and offsets
//! asserted at compile time. Every bit pattern is a valid value (`bytemuck::Pod`), so a buggy or
//! hostile publisher cannot cause undefined behaviour; `validate()` then says whether the values
//! make sense, and a process drops (and counts) whatever does not.

// The derives name `::mole_types`, this crate too.
extern crate self as mole_types;

pub mod control;
pub mod env;
pub mod geometry;
pub mod golden;
#[macro_use]
pub mod kinds;
pub mod fault;
pub mod graph;
pub mod layout;
pub mod link;
pub mod messages;
pub mod settings;
pub mod topics;

pub use control::*;
pub use fault::{Fault, FaultKind, FaultSpec};
pub use geometry::*;
pub use graph::{GRAPH, Role, RoleSpec};
pub use kinds::{ClockMode, EndReason, EstimatorKind, Needs, PlannerKind, UnknownChoice};
pub use messages::*;
pub use mole_types_derive::{Layout, Message, Setting};
pub use topics::Topic;

/// Why a received message was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Invalid {
    /// A float field is NaN or infinite.
    NotFinite(&'static str),
    /// A count field is above the array's capacity.
    CountAboveCapacity(&'static str),
    /// A mode, kind or flag field holds a code this version does not know.
    UnknownCode(&'static str),
    /// A value is outside its physical range (a negative range, a zero resolution...).
    OutOfRange(&'static str),
}

impl core::fmt::Display for Invalid {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Invalid::NotFinite(field) => write!(f, "field `{field}` is not finite"),
            Invalid::CountAboveCapacity(field) => write!(f, "count `{field}` exceeds capacity"),
            Invalid::UnknownCode(field) => write!(f, "field `{field}` holds an unknown code"),
            Invalid::OutOfRange(field) => write!(f, "field `{field}` is out of range"),
        }
    }
}

impl std::error::Error for Invalid {}

/// What every message type offers the runtime.
///
/// # Safety contract (checked by the bounds)
/// `Pod` guarantees every bit pattern is a valid value; `ZeroCopySend` with `#[repr(C)]` lets
/// iceoryx2 place the type in shared memory.
///
/// Derived, never written by hand: `#[derive(Message)]` (mole-types-derive) gives the header
/// accessors, `validate` from `#[message(check = …)]` and the entry in the layout table. A new
/// message is one struct:
///
/// ```
/// use bytemuck::{Pod, Zeroable};
/// use iceoryx2_bb_derive_macros::ZeroCopySend;
/// use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
/// use mole_types::{Header, Invalid, Message, layout::Layout};
///
/// #[repr(C)]
/// #[derive(Debug, Clone, Copy, Pod, Zeroable, ZeroCopySend, Message)]
/// #[type_name("mole.Bump.v1")]
/// #[layout(size = 48)]
/// #[message(check = Bump::check)]
/// pub struct Bump {
///     pub header: Header,
///     pub force: f64,
///     pub sensor: u32,
///     pub _pad: u32,
/// }
///
/// impl Bump {
///     fn check(&self) -> Result<(), Invalid> {
///         mole_types::finite("force", self.force)
///     }
/// }
///
/// let mut bump: Bump = bytemuck::Zeroable::zeroed();
/// bump.header_mut().tick = 7;
/// assert_eq!(bump.header().tick, 7);
/// assert!(bump.validate().is_ok());
/// bump.force = f64::NAN;
/// assert_eq!(bump.validate(), Err(Invalid::NotFinite("force")));
/// let layout = Bump::layout();
/// assert_eq!((layout.type_name, layout.size, layout.fields.len()), ("mole.Bump.v1", 48, 4));
/// assert_eq!(layout.fields[2].offset, 40);
/// ```
///
/// The derive refuses a size other than the one declared (a layout change must be deliberate)…
///
/// ```compile_fail,E0080
/// # use bytemuck::{Pod, Zeroable};
/// # use iceoryx2_bb_derive_macros::ZeroCopySend;
/// # use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
/// # use mole_types::{Header, Message};
/// #[repr(C)]
/// #[derive(Debug, Clone, Copy, Pod, Zeroable, ZeroCopySend, Message)]
/// #[type_name("mole.Bump.v1")]
/// #[layout(size = 40)]
/// pub struct Bump { pub header: Header, pub force: f64, pub sensor: u32, pub _pad: u32 }
/// ```
///
/// …a message without a declared size, or without its header:
///
/// ```compile_fail
/// # use bytemuck::{Pod, Zeroable};
/// # use iceoryx2_bb_derive_macros::ZeroCopySend;
/// # use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
/// # use mole_types::{Header, Message};
/// #[repr(C)]
/// #[derive(Debug, Clone, Copy, Pod, Zeroable, ZeroCopySend, Message)]
/// #[type_name("mole.Bump.v1")]
/// pub struct Bump { pub header: Header, pub force: f64, pub sensor: u32, pub _pad: u32 }
/// ```
///
/// ```compile_fail
/// # use bytemuck::{Pod, Zeroable};
/// # use iceoryx2_bb_derive_macros::ZeroCopySend;
/// # use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
/// # use mole_types::Message;
/// #[repr(C)]
/// #[derive(Debug, Clone, Copy, Pod, Zeroable, ZeroCopySend, Message)]
/// #[type_name("mole.Bump.v1")]
/// #[layout(size = 16)]
/// pub struct Bump { pub force: f64, pub sensor: u32, pub _pad: u32 }
/// ```
pub trait Message:
    bytemuck::Pod
    + iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend
    + core::fmt::Debug
    + layout::Layout
{
    /// The versioned name every language must agree on, e.g. `mole.Scan.v1`: the one written
    /// in the type's `#[type_name("...")]` attribute.
    fn wire_type_name() -> &'static str {
        // SAFETY: reading the name has no precondition; the trait's safety contract (the same
        // layout in every language) is the message rules', checked by `layout`.
        unsafe {
            <Self as iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend>::type_name()
        }
    }
    /// The common header.
    fn header(&self) -> &Header;
    /// The common header, to stamp before publishing.
    fn header_mut(&mut self) -> &mut Header;
    /// Whether the values make sense; a message that fails is dropped and counted.
    fn validate(&self) -> Result<(), Invalid>;
}

/// Checks that a float is finite, naming the field otherwise.
#[inline]
pub fn finite(field: &'static str, value: f64) -> Result<(), Invalid> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(Invalid::NotFinite(field))
    }
}

/// Checks that every float in a slice is finite.
#[inline]
pub fn all_finite<T: Copy + Into<f64>>(field: &'static str, values: &[T]) -> Result<(), Invalid> {
    if values.iter().all(|v| (*v).into().is_finite()) {
        Ok(())
    } else {
        Err(Invalid::NotFinite(field))
    }
}

/// Checks that a count fits its array.
#[inline]
pub fn within(field: &'static str, count: u32, capacity: usize) -> Result<(), Invalid> {
    if (count as usize) <= capacity {
        Ok(())
    } else {
        Err(Invalid::CountAboveCapacity(field))
    }
}

/// Writes `name` into a fixed, NUL-padded byte field (truncating at the capacity).
pub fn write_name(field: &mut [u8], name: &str) {
    field.fill(0);
    let n = name.len().min(field.len());
    field[..n].copy_from_slice(&name.as_bytes()[..n]);
}

/// Reads a fixed, NUL-padded byte field back as text (lossy on invalid UTF-8).
pub fn read_name(field: &[u8]) -> std::borrow::Cow<'_, str> {
    let end = field.iter().position(|b| *b == 0).unwrap_or(field.len());
    String::from_utf8_lossy(&field[..end])
}
