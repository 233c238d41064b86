//! `rooms`: an office floor, a grid of rooms separated by walls with door gaps. The doors of a
//! random spanning tree (depth first) make every room reachable; `extra_doors` more on random
//! closed walls add loops. The start is in the corner room (0, 0), the goal in the room
//! farthest from it through the doors.

use super::lattice::{self, Lattice, Wall};
use super::{
    Bad, ChaCha8Rng, Layout, at_least, check_arena, check_obstacles, index, positive, uniform,
    wider_than_robot,
};
use mole_types::RobotSpec;

/// Parameters of the rooms family.
#[derive(Debug, Clone, PartialEq)]
pub struct RoomsParams {
    /// Rooms along x.
    pub rooms_x: usize,
    /// Rooms along y.
    pub rooms_y: usize,
    /// Inner side of a room (m).
    pub room_size: f64,
    /// Wall thickness (m): the side of the wall squares.
    pub wall_thickness: f64,
    /// Door width (m): more than the robot's diameter, at most `room_size − 2·wall_thickness`.
    pub door_width: f64,
    /// Doors beyond the spanning tree's (loops), on walls that have none.
    pub extra_doors: usize,
}

impl Default for RoomsParams {
    /// 3 × 3 rooms of 3 m, walls 0.2 m thick, doors 0.9 m wide, two extra doors.
    fn default() -> Self {
        RoomsParams {
            rooms_x: 3,
            rooms_y: 3,
            room_size: 3.0,
            wall_thickness: 0.2,
            door_width: 0.9,
            extra_doors: 2,
        }
    }
}

impl RoomsParams {
    /// `key = value` for the file header.
    pub(super) fn describe(&self) -> String {
        format!(
            "rooms.rooms_x = {}, rooms.rooms_y = {}, rooms.room_size = {:?}, \
             rooms.wall_thickness = {:?}, rooms.door_width = {:?}, rooms.extra_doors = {}",
            self.rooms_x,
            self.rooms_y,
            self.room_size,
            self.wall_thickness,
            self.door_width,
            self.extra_doors
        )
    }

    /// Checks the parameters against the robot and the grid.
    pub(super) fn check(&self, robot: &RobotSpec, resolution: f64) -> Result<(), Bad> {
        at_least("rooms.rooms_x", self.rooms_x, 1)?;
        at_least("rooms.rooms_y", self.rooms_y, 1)?;
        if self.rooms_x.saturating_mul(self.rooms_y) < 2 {
            return Err(Bad::new(
                "rooms.rooms_x",
                "at least 2 rooms in all (rooms_x × rooms_y)",
                self.rooms_x,
            ));
        }
        positive("rooms.room_size", self.room_size)?;
        positive("rooms.wall_thickness", self.wall_thickness)?;
        wider_than_robot("rooms.door_width", self.door_width, robot)?;
        let widest = self.room_size - 2.0 * self.wall_thickness;
        if self.door_width > widest {
            return Err(Bad::new(
                "rooms.door_width",
                format!(
                    "at most room_size − 2 × wall_thickness = {widest:?} m (a wall stub each side)"
                ),
                self.door_width,
            ));
        }
        let (w, h) = lattice::extent(
            self.rooms_x,
            self.rooms_y,
            self.room_size,
            self.wall_thickness,
        );
        let size = if self.rooms_x >= self.rooms_y {
            "rooms.rooms_x"
        } else {
            "rooms.rooms_y"
        };
        check_arena(size, w, h, resolution)?;
        check_obstacles(
            "rooms.wall_thickness",
            Lattice::max_squares(
                self.rooms_x,
                self.rooms_y,
                self.room_size,
                self.wall_thickness,
            ),
            self.wall_thickness,
        )
    }

    /// A door at a random place along a wall, a wall stub at least `wall_thickness` long each
    /// side.
    fn door(&self, rng: &mut ChaCha8Rng) -> Wall {
        let half = self.door_width / 2.0;
        let t = self.wall_thickness;
        let centre = uniform(rng, t + half, self.room_size - t - half);
        Wall::Door {
            from: centre - half,
            to: centre + half,
        }
    }

    /// The floor of one draw: the tree's doors, then the extra ones.
    pub(super) fn lattice(&self, rng: &mut ChaCha8Rng) -> Lattice {
        let mut lattice = Lattice::new(
            self.rooms_x,
            self.rooms_y,
            self.room_size,
            self.wall_thickness,
        );
        lattice.carve_tree((0, 0), rng, |rng| self.door(rng));
        let mut closed = lattice.closed_walls();
        for _ in 0..self.extra_doors.min(closed.len()) {
            let (a, b) = closed.swap_remove(index(rng, closed.len()));
            let door = self.door(rng);
            lattice.set_wall(a, b, door);
        }
        lattice
    }

    /// One draw: the floor, the start in room (0, 0), the goal in the farthest room.
    pub(super) fn draw(&self, rng: &mut ChaCha8Rng) -> Layout {
        self.lattice(rng).layout()
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Family, WorldSpec, generate};
    use super::*;
    use crate::free_space::FreeSpace;
    use rand::SeedableRng;

    /// Every room is reachable through the doors: a spanning tree's `rooms − 1` doors and the
    /// extra ones (as many as there are closed walls).
    #[test]
    fn every_room_is_reachable_through_the_doors() {
        for (x, y, extra) in [(3, 3, 2), (2, 1, 5), (4, 2, 0), (3, 3, 100)] {
            let p = RoomsParams {
                rooms_x: x,
                rooms_y: y,
                extra_doors: extra,
                ..RoomsParams::default()
            };
            let walls = (x - 1) * y + x * (y - 1);
            for seed in 0..30 {
                let lattice = p.lattice(&mut ChaCha8Rng::seed_from_u64(seed));
                assert!(lattice.distances((0, 0)).iter().all(Option::is_some));
                assert_eq!(lattice.openings(), (x * y - 1 + extra).min(walls));
            }
        }
    }

    /// A robot just narrower than the doors goes from room to room; one just wider is shut in
    /// its room.
    #[test]
    fn the_door_width_is_honoured() {
        let spec = WorldSpec::new(Family::Rooms);
        let half = spec.rooms.door_width / 2.0;
        for seed in 0..5 {
            let s = generate(&spec, seed).unwrap();
            let goal = s.goal.unwrap();
            let mut thin = s.clone();
            thin.robot.radius = half - 0.02;
            assert!(FreeSpace::with_resolution(&thin, 0.01).goal_reachable(&goal));
            let mut fat = s.clone();
            fat.robot.radius = half + 0.02;
            let space = FreeSpace::with_resolution(&fat, 0.01);
            assert!(
                fat.disk_is_free(s.start.x, s.start.y),
                "the room itself is wide"
            );
            assert!(!space.goal_reachable(&goal), "seed {seed}");
            // Every wall piece is a row of wall-thickness squares: no stub shorter than a square.
            let t = spec.rooms.wall_thickness;
            assert!(s.obstacles.iter().all(|o| o.side == t), "seed {seed}");
            // Shut in the start room: less than its floor.
            let room = spec.rooms.room_size;
            assert!(space.reachable_area() < room * room, "seed {seed}");
        }
    }

    /// The goal is in the room farthest from the start through the doors: on the default floor
    /// at least two doors away.
    #[test]
    fn the_goal_is_in_a_far_room() {
        let spec = WorldSpec::new(Family::Rooms);
        for seed in 0..30 {
            let lattice = spec.rooms.lattice(&mut ChaCha8Rng::seed_from_u64(seed));
            let far = lattice.farthest((0, 0));
            let dist = lattice.distances((0, 0));
            assert!(dist[lattice.at(far)].unwrap() >= 2, "seed {seed}");
            assert_eq!(dist.iter().flatten().max(), dist[lattice.at(far)].as_ref());
        }
    }
}
