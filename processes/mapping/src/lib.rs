//! Mapping: contact grid (algorithms §2) and frontier grid (algorithms §5.2).
//!
//! Both grids cover the arena `[0, W] × [0, H]` at the world's grid resolution and are built from
//! the *estimated* pose. The frontier grid ([`FrontierGrid`]) fuses lidar, footprint and touch in
//! log-odds and publishes algorithms §5.2's 0 unexplored / 1 free / 2 occupied; the contact grid
//! ([`ContactGrid`]) is algorithms §2.2's map M_t of touched cells (0 free or unknown, 1 occupied).
//! Nothing here allocates after `new`; every input that is not finite is ignored.

pub mod contact;
pub mod frontier;
pub mod geometry;
pub mod maps;
pub mod settings;

pub use contact::{ContactGrid, estimate_contacts};
pub use frontier::{FrontierGrid, LogOddsParams};
pub use geometry::GridGeometry;
pub use maps::Maps;
pub use settings::Settings;

/// Why a grid could not be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MappingError {
    /// A size (arena side, resolution) is zero, negative or not finite.
    #[error("{what} must be positive and finite, got {value}")]
    NotPositive { what: &'static str, value: f64 },
    /// The arena at this resolution needs more cells than a `Grid` message holds.
    #[error("grid of {width} × {height} cells exceeds the {max} cells a Grid message holds")]
    TooManyCells { width: f64, height: f64, max: usize },
    /// A log-odds parameter is out of its range.
    #[error("invalid log-odds parameters: {0}")]
    InvalidParams(&'static str),
}

/// A stable 64-bit hash of a grid's cells (FNV-1a, Fowler–Noll–Vo), for determinism checks.
pub fn grid_hash(cells: &[u8]) -> u64 {
    const OFFSET_BASIS: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;
    cells
        .iter()
        .fold(OFFSET_BASIS, |h, &b| (h ^ b as u64).wrapping_mul(PRIME))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_hash_is_fnv1a_and_changes_with_one_cell() {
        // Reference values of 64-bit FNV-1a.
        assert_eq!(grid_hash(&[]), 0xcbf2_9ce4_8422_2325);
        assert_eq!(grid_hash(b"a"), 0xaf63_dc4c_8601_ec8c);
        let mut cells = vec![0u8; 100 * 100];
        let h0 = grid_hash(&cells);
        assert_eq!(h0, grid_hash(&cells.clone()));
        for i in [0, 1, 5000, 9999] {
            cells[i] = 1;
            assert_ne!(grid_hash(&cells), h0, "cell {i}");
            cells[i] = 2;
            assert_ne!(grid_hash(&cells), h0, "cell {i}");
            cells[i] = 0;
        }
        assert_eq!(grid_hash(&cells), h0);
    }
}
