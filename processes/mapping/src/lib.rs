//! Mapping: contact grid (seed §2) and frontier grid (seed §5.2)
