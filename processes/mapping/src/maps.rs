//! Both grids of the mapping process, built together from one step's readings.

use crate::{ContactGrid, FrontierGrid, MappingError, Settings};
use mole_types::{Grid, Pose2, Scan, Tactile, WorldMap};

/// The frontier grid and the contact grid of one arena, and what one step adds to them.
pub struct Maps {
    pub frontier: FrontierGrid,
    pub contact: ContactGrid,
    robot_radius: f64,
    /// A tactile reading above this force (N) is a touch.
    touch_threshold: f64,
}

impl Maps {
    /// New settings from the next step on (`mole param set`).
    pub fn set_settings(&mut self, settings: &Settings) -> Result<(), MappingError> {
        self.frontier.set_params(settings.log_odds)?;
        self.touch_threshold = settings.touch_threshold;
        Ok(())
    }

    /// Empty grids over the arena of `map`, at its grid resolution, built as `settings` say.
    pub fn new(map: &WorldMap, settings: &Settings) -> Result<Maps, MappingError> {
        let (w, h, res) = (map.arena_width, map.arena_height, map.grid_resolution);
        Ok(Maps {
            frontier: FrontierGrid::with_params(w, h, res, settings.log_odds)?,
            contact: ContactGrid::new(w, h, res)?,
            robot_radius: map.robot.radius,
            touch_threshold: settings.touch_threshold,
        })
    }

    /// Goes on from the grids of the process this one replaces; returns whether both were
    /// taken (a grid of another arena or kind is not).
    pub fn restore(&mut self, frontier: Option<&Grid>, contact: Option<&Grid>) -> bool {
        let frontier = frontier.is_some_and(|g| self.frontier.restore(g));
        let contact = contact.is_some_and(|g| self.contact.restore(g));
        frontier && contact
    }

    /// One step: the footprint at the estimated pose, the scan and the touches of this step
    /// (`None` when the step has none); a touched cell is occupied in the frontier grid too.
    pub fn integrate(&mut self, pose: Pose2, scan: Option<&Scan>, tactile: Option<&Tactile>) {
        self.frontier.integrate_footprint(pose, self.robot_radius);
        if let Some(scan) = scan {
            self.frontier.integrate_scan(pose, scan);
        }
        if let Some(tactile) = tactile {
            let touched = self
                .contact
                .integrate_tactile(pose, tactile, self.touch_threshold);
            for &(x, y) in touched {
                self.frontier.mark_occupied(x, y);
            }
        }
    }
}
