//! The launcher's own node names, at the bottom of its layers beside its errors.

/// The launcher's own node name; its statistics are not a role's.
pub const LAUNCHER_NODE: &str = "launcher";

/// The node name `mole top` uses; it does not count as a stack in the namespace.
pub const TOP_ROLE: &str = "top";
