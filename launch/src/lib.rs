//! The mole launcher: launch files, supervision, swapping, measuring
