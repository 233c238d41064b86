//! World simulation: scenarios, unicycle dynamics, contact resolution, ground truth.
//!
//! - [`scenario`]: the scenario file format (TOML), its defaults, validation and located errors,
//!   and [`Scenario::write_world_map`] which fills the `world/map` message in place.
//! - [`rosmap`]: ROS map_server maps (YAML + PGM) that a scenario may load as obstacles.
//! - [`World`]: one disk robot with unicycle kinematics in the arena of algorithms §1.3 (a rectangle
//!   with axis-aligned squares); `step` applies a command, resolves contacts and records them.
//! - [`FreeSpace`]: the robot's free configuration space on a raster, flood-filled from the start
//!   (which scenario regions the robot can reach at all).

mod broadphase;
pub mod free_space;
pub mod rosmap;
pub mod scenario;
pub mod world;

pub use free_space::FreeSpace;
pub use rosmap::{MapError, OccupancyMap, load_ros_map};
pub use scenario::{Goal, Location, Scenario, ScenarioError, load_scenario, parse_scenario};
pub use world::{CONTACT_SKIN, World};

/// Counts heap allocations per thread, so tests can prove a hot path allocates nothing.
#[cfg(test)]
pub(crate) mod alloc_count {
    use std::alloc::{GlobalAlloc, Layout, System};
    use std::cell::Cell;

    thread_local! {
        static COUNT: Cell<usize> = const { Cell::new(0) };
    }

    struct Counting;

    // SAFETY: forwards to the system allocator; only bumps a const-initialised thread-local.
    unsafe impl GlobalAlloc for Counting {
        unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
            let _ = COUNT.try_with(|c| c.set(c.get() + 1));
            // SAFETY: same contract as the caller's.
            unsafe { System.alloc(layout) }
        }
        unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
            // SAFETY: same contract as the caller's.
            unsafe { System.dealloc(ptr, layout) }
        }
        unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
            let _ = COUNT.try_with(|c| c.set(c.get() + 1));
            // SAFETY: same contract as the caller's.
            unsafe { System.realloc(ptr, layout, new_size) }
        }
    }

    #[global_allocator]
    static ALLOCATOR: Counting = Counting;

    /// Allocations made by this thread so far.
    pub(crate) fn allocations() -> usize {
        COUNT.with(Cell::get)
    }

    #[test]
    fn the_counter_sees_allocations() {
        let before = allocations();
        let v: Vec<u64> = Vec::with_capacity(16);
        assert_eq!(allocations(), before + 1);
        drop(v);
    }
}
