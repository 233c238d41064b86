//! `cellular`: a cellular-automaton field as BARN generates its worlds (Perille et al. 2020,
//! "Benchmarking Metric Ground Navigation"): a coarse grid of `cell_size` cells, each occupied
//! with the fill probability (drawn per world in `[fill_min, fill_max]`), then smoothed
//! `smoothing_steps` times with the birth/survival rule on the 8 neighbours (a free cell becomes
//! occupied with at least `birth` occupied neighbours, an occupied one stays with at least
//! `survival`; cells off the grid count as free); each occupied cell is one square. The field
//! spans the arena's width between two free aprons: the start in the lower one, the goal in the
//! upper one, so every path crosses the field; [`super::generate`]'s path check on the inflated
//! grid refuses the draws the robot cannot cross.

use super::{Bad, ChaCha8Rng, Layout, at_least, check_arena, positive, uniform, wider_than_robot};
use mole_types::{MAX_GRID_CELLS, MAX_OBSTACLES, Pose2, RobotSpec, Square};
use rand::RngExt;

/// Parameters of the cellular family.
#[derive(Debug, Clone, PartialEq)]
pub struct CellularParams {
    /// Field cells along x.
    pub cols: usize,
    /// Field cells along y.
    pub rows: usize,
    /// Cell side (m): the side of each square.
    pub cell_size: f64,
    /// Least initial fill probability.
    pub fill_min: f64,
    /// Greatest initial fill probability.
    pub fill_max: f64,
    /// Smoothing steps of the automaton.
    pub smoothing_steps: usize,
    /// Occupied neighbours (of 8) that make a free cell occupied (9: never).
    pub birth: u32,
    /// Occupied neighbours (of 8) an occupied cell needs to stay occupied (0: always).
    pub survival: u32,
    /// Depth of the free strips below and above the field (m), where the start and goal stand.
    pub apron: f64,
}

impl Default for CellularParams {
    /// BARN's field: 30 × 30 cells of 0.15 m, fill 0.15 to 0.25, smoothed twice with B4/S2
    /// (isolated cells vanish, clusters grow into blobs), aprons of 1 m. Over seeds 0..50 for
    /// the default robot (radius 0.25 m, clearance 0.1 m), 31 first draws cannot be crossed
    /// and are drawn again, 13 of them crossable by the bare radius through gaps of 0.6 m
    /// (4 cells, 0.05 m to spare each side): the test below.
    fn default() -> Self {
        CellularParams {
            cols: 30,
            rows: 30,
            cell_size: 0.15,
            fill_min: 0.15,
            fill_max: 0.25,
            smoothing_steps: 2,
            birth: 4,
            survival: 2,
            apron: 1.0,
        }
    }
}

/// Smoothing steps at most (each costs one pass over the field).
const MAX_SMOOTHING_STEPS: usize = 1000;

impl CellularParams {
    /// `key = value` for the file header.
    pub(super) fn describe(&self) -> String {
        format!(
            "cellular.cols = {}, cellular.rows = {}, cellular.cell_size = {:?}, \
             cellular.fill_min = {:?}, cellular.fill_max = {:?}, cellular.smoothing_steps = {}, \
             cellular.birth = {}, cellular.survival = {}, cellular.apron = {:?}",
            self.cols,
            self.rows,
            self.cell_size,
            self.fill_min,
            self.fill_max,
            self.smoothing_steps,
            self.birth,
            self.survival,
            self.apron
        )
    }

    /// Arena width and height (m): the field and its two aprons.
    fn extent(&self) -> (f64, f64) {
        (
            self.cols as f64 * self.cell_size,
            self.rows as f64 * self.cell_size + 2.0 * self.apron,
        )
    }

    /// Checks the parameters against the robot and the grid.
    pub(super) fn check(&self, robot: &RobotSpec, resolution: f64) -> Result<(), Bad> {
        at_least("cellular.cols", self.cols, 1)?;
        at_least("cellular.rows", self.rows, 1)?;
        positive("cellular.cell_size", self.cell_size)?;
        for (name, v) in [
            ("cellular.fill_min", self.fill_min),
            ("cellular.fill_max", self.fill_max),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(Bad::new(name, "a probability in [0, 1]", v));
            }
        }
        if self.fill_max < self.fill_min {
            return Err(Bad::new(
                "cellular.fill_max",
                format!("at least fill_min = {:?}", self.fill_min),
                self.fill_max,
            ));
        }
        if self.smoothing_steps > MAX_SMOOTHING_STEPS {
            return Err(Bad::new(
                "cellular.smoothing_steps",
                format!("at most {MAX_SMOOTHING_STEPS}"),
                self.smoothing_steps,
            ));
        }
        for (name, v) in [
            ("cellular.birth", self.birth),
            ("cellular.survival", self.survival),
        ] {
            if v > 9 {
                return Err(Bad::new(name, "a neighbour count in 0..=9 (9: never)", v));
            }
        }
        if self.cols.saturating_mul(self.rows) > MAX_GRID_CELLS {
            return Err(Bad::new(
                "cellular.cols",
                format!("a field of at most {MAX_GRID_CELLS} cells (cols × rows)"),
                self.cols,
            ));
        }
        wider_than_robot("cellular.apron", self.apron, robot)?;
        let (w, h) = self.extent();
        wider_than_robot("cellular.cols", w, robot).map_err(|mut bad| {
            bad.expected = format!("a field ({} m wide) {}", w, bad.expected);
            bad.found = format!("{}", self.cols);
            bad
        })?;
        check_arena("cellular.cols", w, h, resolution)
    }

    /// The automaton of one draw: occupied cells, row-major from the lower left.
    pub(super) fn field(&self, rng: &mut ChaCha8Rng) -> Vec<bool> {
        let (cols, rows) = (self.cols, self.rows);
        let fill = uniform(rng, self.fill_min, self.fill_max);
        let mut cells: Vec<bool> = (0..cols * rows)
            .map(|_| rng.random::<f64>() < fill)
            .collect();
        let mut next = cells.clone();
        for _ in 0..self.smoothing_steps {
            for j in 0..rows {
                for i in 0..cols {
                    let mut n = 0;
                    for (di, dj) in [
                        (-1, -1),
                        (0, -1),
                        (1, -1),
                        (-1, 0),
                        (1, 0),
                        (-1, 1),
                        (0, 1),
                        (1, 1),
                    ] {
                        let (x, y) = (i as i64 + di, j as i64 + dj);
                        if x >= 0
                            && y >= 0
                            && (x as usize) < cols
                            && (y as usize) < rows
                            && cells[y as usize * cols + x as usize]
                        {
                            n += 1;
                        }
                    }
                    let k = j * cols + i;
                    next[k] = if cells[k] {
                        n >= self.survival
                    } else {
                        n >= self.birth
                    };
                }
            }
            std::mem::swap(&mut cells, &mut next);
        }
        cells
    }

    /// One draw: the field's squares, the start below it, the goal above it; more squares than
    /// a world holds is a failed draw.
    pub(super) fn draw(&self, rng: &mut ChaCha8Rng) -> Result<Layout, String> {
        let cells = self.field(rng);
        let (w, h) = self.extent();
        let c = self.cell_size;
        let occupied = cells.iter().filter(|&&o| o).count();
        if occupied > MAX_OBSTACLES {
            return Err(format!(
                "{occupied} occupied cells, more squares than a world holds ({MAX_OBSTACLES})"
            ));
        }
        let mut obstacles = Vec::with_capacity(occupied);
        for j in 0..self.rows {
            for i in 0..self.cols {
                if cells[j * self.cols + i] {
                    let (x, y) = ((i as f64 + 0.5) * c, self.apron + (j as f64 + 0.5) * c);
                    obstacles.push(Square::new(x, y, c));
                }
            }
        }
        Ok(Layout {
            width: w,
            height: h,
            start: Pose2::new(w / 2.0, self.apron / 2.0, std::f64::consts::FRAC_PI_2),
            goal: (w / 2.0, h - self.apron / 2.0),
            obstacles,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::super::{
        Family, GenerateError, MAX_ATTEMPTS, WorldSpec, check_solvable, generate, scenario_of,
    };
    use super::*;
    use rand::SeedableRng;

    /// A field filled at 0.9 is never crossable: every draw is refused, and the error names the
    /// family and the seed.
    #[test]
    fn an_unsolvable_field_is_refused() {
        let mut spec = WorldSpec::new(Family::Cellular);
        spec.cellular.fill_min = 0.9;
        spec.cellular.fill_max = 0.9;
        match generate(&spec, 5) {
            Err(e @ GenerateError::Unsolvable { .. }) => {
                let text = e.to_string();
                assert!(
                    text.starts_with(&format!(
                        "world `cellular` seed 5: no solvable draw in {MAX_ATTEMPTS} attempts"
                    )),
                    "{text}"
                );
                assert!(text.contains("not reachable"), "{text}");
            }
            other => panic!("expected an unsolvable world, got {other:?}"),
        }
    }

    /// The path check guards the defaults too: with the 0.25 m robot many first draws cannot be
    /// crossed, and generate retries them into worlds that can; and the clearance refuses draws
    /// the bare radius passes (BARN's fields leave gaps a few centimetres wider than the robot).
    #[test]
    fn the_path_check_refuses_default_draws() {
        let spec = WorldSpec::new(Family::Cellular);
        let (mut refused, mut too_tight) = (0, 0);
        for seed in 0..50 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            rng.set_stream(0);
            let layout = spec.draw(&mut rng).unwrap();
            let first = scenario_of(&spec, seed, layout);
            let s = generate(&spec, seed).unwrap();
            if check_solvable(&first, spec.min_coverage, spec.clearance).is_err() {
                refused += 1;
                assert_ne!(s.obstacles, first.obstacles, "seed {seed}: drawn again");
                if check_solvable(&first, spec.min_coverage, 0.0).is_ok() {
                    too_tight += 1;
                }
            } else {
                assert_eq!(s.obstacles, first.obstacles, "seed {seed}: the first draw");
            }
        }
        eprintln!(
            "cellular: {refused} of 50 first draws refused, {too_tight} of them crossable \
             without the clearance"
        );
        assert!(refused >= 5, "{refused} of 50 first draws refused");
        assert!(
            too_tight >= 5,
            "{too_tight} of 50 first draws refused for the clearance alone"
        );
    }

    /// The rule: an isolated cell dies, a free cell ringed by occupied ones is born.
    #[test]
    fn the_automaton_applies_birth_and_survival() {
        let p = CellularParams {
            cols: 5,
            rows: 5,
            fill_min: 0.0,
            fill_max: 0.0,
            smoothing_steps: 0,
            ..CellularParams::default()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        assert!(p.field(&mut rng).iter().all(|&c| !c), "fill 0: empty");
        let full = CellularParams {
            fill_min: 1.0,
            fill_max: 1.0,
            smoothing_steps: 3,
            ..p.clone()
        };
        assert!(
            full.field(&mut rng).iter().all(|&c| c),
            "fill 1: full, it survives"
        );
        let dying = CellularParams {
            survival: 9,
            smoothing_steps: 1,
            ..full.clone()
        };
        assert!(
            dying.field(&mut rng).iter().all(|&c| !c),
            "survival 9: all die"
        );
    }
}
