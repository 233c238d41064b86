use super::*;
use crate::free_space::FreeSpace;
use crate::scenario::{load_scenario, parse_scenario};
use mole_types::BeaconSite;
use proptest::prelude::*;
use std::path::Path;

/// Every family, lit and dark, with its defaults.
fn every_spec() -> Vec<WorldSpec> {
    Family::ALL
        .into_iter()
        .flat_map(|f| {
            [false, true].map(|dark| WorldSpec {
                dark,
                ..WorldSpec::new(f)
            })
        })
        .collect()
}

fn world(spec: &WorldSpec, seed: u64) -> Scenario {
    generate(spec, seed).unwrap_or_else(|e| panic!("{e}"))
}

/// FNV-1a, 64 bits: a hash with no platform or version in it.
fn fnv(text: &str) -> u64 {
    text.bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

#[test]
fn family_names_and_specs_parse() {
    for f in Family::ALL {
        assert_eq!(f.to_string().parse::<Family>(), Ok(f));
        let lit = WorldSpec::parse(f.name()).unwrap();
        assert_eq!((lit.family, lit.dark), (f, false));
        let dark = WorldSpec::parse(&format!("{f}-dark")).unwrap();
        assert_eq!((dark.family, dark.dark), (f, true));
        assert_eq!(dark.to_string(), format!("{f}-dark"));
        assert_eq!(dark.scenario_name(42), format!("{f}-dark-0042"));
        assert_eq!(lit.scenario_name(123_456), format!("{f}-123456"));
    }
    for bad in ["", "Maze", "maze-dark-dark", "dark", "mazes", "maze-"] {
        let e = WorldSpec::parse(bad).unwrap_err();
        assert!(
            e.contains(&format!("`{bad}`"))
                && e.contains("maze, rooms, clutter, cellular, corridors"),
            "{e}"
        );
    }
    assert!(
        "x".parse::<Family>()
            .unwrap_err()
            .contains("expected one of maze")
    );
}

#[test]
fn the_same_seed_gives_the_same_world_and_another_seed_another() {
    for spec in every_spec() {
        let a = world(&spec, 7);
        assert_eq!(a, world(&spec, 7), "{spec}");
        assert_eq!(a.name, spec.scenario_name(7));
        assert_eq!(a.seed, 7);
        let b = world(&spec, 8);
        assert!(
            a.obstacles != b.obstacles || a.start != b.start || a.goal != b.goal,
            "{spec}: seeds 7 and 8 gave the same world"
        );
        assert_ne!(a.beacons, b.beacons, "{spec}");
    }
}

/// The worlds of seed 42 as files, hashed: a change of the generator, of the random stream or of
/// the floating-point results on another machine changes them. (Update the table when the
/// generator changes on purpose, and say so.)
#[test]
fn seed_42_gives_the_recorded_worlds() {
    let recorded: [(Family, u64); 5] = [
        (Family::Maze, 8_528_958_222_465_149_881),
        (Family::Rooms, 4_402_397_990_692_872_049),
        (Family::Clutter, 12_853_751_607_979_125_964),
        (Family::Cellular, 16_672_740_276_945_727_685),
        (Family::Corridors, 2_772_096_909_061_111_462),
    ];
    let mut found = Vec::new();
    for (family, _) in recorded {
        let spec = WorldSpec::new(family);
        found.push((family, fnv(&world_toml(&spec, 42, &world(&spec, 42)))));
    }
    assert_eq!(found, recorded);
}

/// The acceptance sweep: every family, lit and dark, seeds 0..50: generated, the start free, the
/// goal reachable, within every capacity, and the file reads back to the same scenario.
#[test]
fn every_family_gives_solvable_repeatable_worlds_for_seeds_0_to_50() {
    for spec in every_spec() {
        for seed in 0..50 {
            let s = world(&spec, seed);
            let what = s.name.clone();
            assert_eq!(s.name, spec.scenario_name(seed));
            assert_eq!(s.seed, seed);
            assert!(s.disk_is_free(s.start.x, s.start.y), "{what}: start");
            let goal = s.goal.expect("a goal");
            assert!(s.disk_is_free(goal.x, goal.y), "{what}: goal");
            let space = FreeSpace::new(&s);
            assert!(space.goal_reachable(&goal), "{what}: goal unreachable");
            assert!(
                space
                    .shortest_path((s.start.x, s.start.y), (goal.x, goal.y))
                    .is_some(),
                "{what}: no path"
            );
            assert!(s.obstacles.len() <= MAX_OBSTACLES, "{what}");
            assert_eq!(s.beacons.len(), spec.beacons, "{what}: beacons");
            for (i, b) in s.beacons.iter().enumerate() {
                assert_eq!(b.id as usize, i);
                assert!(space.is_reachable(b.x, b.y), "{what}: beacon {i}");
            }
            let (gw, gh) = s.grid_size();
            assert!(gw * gh <= MAX_GRID_CELLS, "{what}: {gw} × {gh}");
            assert_eq!(
                s.sensors.lidar_beams == 0 && s.sensors.fix_period_ticks == 0,
                spec.dark,
                "{what}: sensors"
            );
            for text in [world_toml(&spec, seed, &s), scenario_toml(&s)] {
                let back = parse_scenario(&text, &s.path).unwrap_or_else(|e| panic!("{e}"));
                assert_eq!(back, s, "{what}: round trip");
            }
        }
    }
}

#[test]
fn the_file_header_says_how_the_world_was_made() {
    let spec = WorldSpec::parse("rooms-dark").unwrap();
    let s = world(&spec, 3);
    let text = world_toml(&spec, 3, &s);
    let header: Vec<&str> = text.lines().take_while(|l| l.starts_with('#')).collect();
    let header = header.join("\n");
    for part in [
        "\"rooms-dark-0003\"",
        "family `rooms-dark`",
        "seed 3",
        "rooms.door_width = 0.9",
        "robot.radius = 0.25",
        "beacons = 8",
        "dark = true",
        "mole up --scenario FILE",
    ] {
        assert!(header.contains(part), "{part} missing from\n{header}");
    }
    // The arrays come before the first table header.
    let first_table = text.find("\n[").unwrap();
    assert!(text.find("obstacles = [").unwrap() < first_table);
    assert!(text.find("beacons = [").unwrap() < first_table);
}

/// `scenario_toml` writes any scenario, not only generated ones: every file in scenarios/ (the
/// ROS map's pixels become listed squares), and a hand-made one with an awkward name and no goal.
#[test]
fn any_scenario_round_trips_through_its_file() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios");
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let s = load_scenario(&path).unwrap_or_else(|e| panic!("{e}"));
        let back = parse_scenario(&scenario_toml(&s), &path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back, s, "{}", path.display());
        seen += 1;
    }
    assert!(seen >= 8, "{seen}");
    let odd = Scenario {
        name: "a \"quoted\" \\ name\twith\u{7}control".to_owned(),
        path: "odd.toml".into(),
        seed: u64::MAX,
        dt: 0.1 + 0.2,
        obstacles: vec![
            Square::new(1.0 / 3.0, 2.0, 1e-7),
            Square::new(5.5, 5.5, 0.5),
        ],
        beacons: vec![BeaconSite {
            x: 9.75,
            y: 0.1,
            id: 0,
            _pad: 0,
        }],
        ..Scenario::default()
    };
    let back = parse_scenario(&scenario_toml(&odd), &odd.path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(back, odd);
}

/// Any seed, up to `u64::MAX`, names its world and reads back from the file.
#[test]
fn every_seed_fits_the_file() {
    let spec = WorldSpec::new(Family::Maze);
    let s = world(&spec, u64::MAX);
    assert_eq!(s.name, "maze-18446744073709551615");
    let back = parse_scenario(&world_toml(&spec, u64::MAX, &s), &s.path).unwrap();
    assert_eq!(back.seed, u64::MAX);
}

#[test]
fn dark_worlds_are_the_lit_worlds_without_lidar_or_fix() {
    for family in Family::ALL {
        for seed in 0..10 {
            let lit = world(&WorldSpec::new(family), seed);
            let dark = world(
                &WorldSpec {
                    dark: true,
                    ..WorldSpec::new(family)
                },
                seed,
            );
            assert!(lit.sensors.lidar_beams > 0 && lit.sensors.fix_period_ticks > 0);
            assert_eq!(dark.sensors.lidar_beams, 0, "{}", dark.name);
            assert_eq!(dark.sensors.fix_period_ticks, 0, "{}", dark.name);
            assert_eq!(dark.name, format!("{family}-dark-{seed:04}"));
            assert_eq!(dark.obstacles, lit.obstacles, "{}", dark.name);
            assert!(!dark.beacons.is_empty());
            assert_eq!(dark.beacons, lit.beacons, "{}", dark.name);
            assert_eq!((dark.start, dark.goal), (lit.start, lit.goal));
            let mut relit = dark.clone();
            relit.name = lit.name.clone();
            relit.path = lit.path.clone();
            relit.sensors = lit.sensors;
            assert_eq!(relit, lit, "nothing else differs");
        }
    }
}

/// Every bad parameter is refused before anything is drawn, naming the parameter.
#[test]
fn bad_parameters_name_the_parameter() {
    type Edit = fn(&mut WorldSpec);
    let cases: Vec<(Family, Edit, &str)> = vec![
        (
            Family::Maze,
            |s| s.maze.corridor_width = 0.4,
            "maze.corridor_width",
        ),
        (
            Family::Maze,
            |s| s.maze.corridor_width = 0.5,
            "maze.corridor_width",
        ),
        (
            Family::Maze,
            |s| s.maze.corridor_width = f64::NAN,
            "maze.corridor_width",
        ),
        (
            Family::Maze,
            |s| s.maze.wall_thickness = -0.5,
            "maze.wall_thickness",
        ),
        (Family::Maze, |s| s.maze.cells = 1, "maze.cells"),
        (Family::Maze, |s| s.maze.cells = 40, "maze.cells"),
        (Family::Maze, |s| s.maze.cells = usize::MAX, "maze.cells"),
        (
            Family::Maze,
            |s| s.maze.wall_thickness = 0.001,
            "maze.cells",
        ),
        (
            Family::Rooms,
            |s| s.rooms.door_width = 0.3,
            "rooms.door_width",
        ),
        (
            Family::Rooms,
            |s| s.rooms.door_width = 2.8,
            "rooms.door_width",
        ),
        (
            Family::Rooms,
            |s| s.rooms.room_size = -3.0,
            "rooms.room_size",
        ),
        (Family::Rooms, |s| s.rooms.rooms_x = 0, "rooms.rooms_x"),
        (
            Family::Rooms,
            |s| {
                s.rooms.rooms_x = 1;
                s.rooms.rooms_y = 1
            },
            "rooms.rooms_x",
        ),
        (
            Family::Rooms,
            |s| s.rooms.rooms_y = usize::MAX,
            "rooms.rooms_y",
        ),
        (Family::Rooms, |s| s.rooms.room_size = 10.0, "rooms.rooms_x"),
        (
            Family::Clutter,
            |s| s.clutter.min_gap = 0.4,
            "clutter.min_gap",
        ),
        (
            Family::Clutter,
            |s| s.clutter.max_size = 0.2,
            "clutter.max_size",
        ),
        (
            Family::Clutter,
            |s| s.clutter.min_size = 0.0,
            "clutter.min_size",
        ),
        (
            Family::Clutter,
            |s| s.clutter.density = 1.5,
            "clutter.density",
        ),
        (
            Family::Clutter,
            |s| s.clutter.density = f64::NAN,
            "clutter.density",
        ),
        (
            Family::Clutter,
            |s| s.clutter.width = -10.0,
            "clutter.width",
        ),
        (
            Family::Clutter,
            |s| s.clutter.height = 1.0,
            "clutter.height",
        ),
        (
            Family::Clutter,
            |s| s.clutter.width = 100.0,
            "clutter.width",
        ),
        (
            Family::Cellular,
            |s| s.cellular.fill_max = 1.5,
            "cellular.fill_max",
        ),
        (
            Family::Cellular,
            |s| s.cellular.fill_min = 0.3,
            "cellular.fill_max",
        ),
        (
            Family::Cellular,
            |s| s.cellular.birth = 10,
            "cellular.birth",
        ),
        (
            Family::Cellular,
            |s| s.cellular.apron = 0.3,
            "cellular.apron",
        ),
        (
            Family::Cellular,
            |s| s.cellular.cell_size = f64::INFINITY,
            "cellular.cell_size",
        ),
        (Family::Cellular, |s| s.cellular.cols = 0, "cellular.cols"),
        (Family::Cellular, |s| s.cellular.cols = 3, "cellular.cols"),
        (
            Family::Cellular,
            |s| s.cellular.cols = 1000,
            "cellular.cols",
        ),
        (
            Family::Cellular,
            |s| {
                s.cellular.cols = 1 << 40;
                s.cellular.cell_size = 1e-12
            },
            "cellular.cols",
        ),
        (
            Family::Cellular,
            |s| s.cellular.smoothing_steps = usize::MAX,
            "cellular.smoothing_steps",
        ),
        (
            Family::Corridors,
            |s| s.corridors.corridor_width = 0.5,
            "corridors.corridor_width",
        ),
        (
            Family::Corridors,
            |s| s.corridors.branch_length = 0,
            "corridors.branch_length",
        ),
        (
            Family::Corridors,
            |s| s.corridors.cols = 1,
            "corridors.cols",
        ),
        (
            Family::Corridors,
            |s| s.corridors.rows = 0,
            "corridors.rows",
        ),
        (
            Family::Corridors,
            |s| s.corridors.cols = 60,
            "corridors.cols",
        ),
        (Family::Maze, |s| s.robot.radius = -0.25, "robot.radius"),
        (
            Family::Rooms,
            |s| s.robot.max_speed = f64::NAN,
            "robot.max_speed",
        ),
        (
            Family::Clutter,
            |s| s.robot.max_alpha = 0.0,
            "robot.max_alpha",
        ),
        (Family::Cellular, |s| s.beacons = 33, "beacons"),
        (
            Family::Corridors,
            |s| s.grid_resolution = 0.0,
            "grid_resolution",
        ),
        (
            Family::Corridors,
            |s| s.grid_resolution = 0.01,
            "corridors.cols",
        ),
        (Family::Maze, |s| s.min_coverage = 1.5, "min_coverage"),
    ];
    for (family, edit, parameter) in cases {
        let mut spec = WorldSpec::new(family);
        edit(&mut spec);
        match generate(&spec, 1) {
            Err(e @ GenerateError::Parameter { .. }) => {
                let text = e.to_string();
                assert!(
                    text.starts_with(&format!(
                        "world `{family}`: parameter `{parameter}`: expected "
                    )),
                    "{parameter}: {text}"
                );
            }
            other => panic!("{parameter}: expected a parameter error, got {other:?}"),
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// No parameter panics: each is drawn from values at and beyond every edge.
    #[test]
    fn no_parameter_panics(
        family in 0usize..5,
        floats in proptest::collection::vec(0usize..11, 12),
        counts in proptest::collection::vec(0usize..8, 8),
        seed in any::<u64>(),
    ) {
        const F: [f64; 11] =
            [-1.0, 0.0, 1e-300, 0.1, 0.3, 0.6, 1.0, 3.0, 1e300, f64::NAN, f64::INFINITY];
        const N: [usize; 8] = [0, 1, 2, 3, 8, 40, 1 << 33, usize::MAX];
        let f = |k: usize| F[floats[k]];
        let n = |k: usize| N[counts[k]];
        let mut spec = WorldSpec::new(Family::ALL[family]);
        spec.robot.radius = f(0) / 4.0;
        spec.maze = MazeParams { cells: n(0), corridor_width: f(1), wall_thickness: f(2) };
        spec.rooms = RoomsParams {
            rooms_x: n(0), rooms_y: n(1), room_size: f(1) * 3.0, wall_thickness: f(2),
            door_width: f(3), extra_doors: n(2),
        };
        spec.clutter = ClutterParams {
            width: f(4) * 4.0, height: f(5) * 4.0, min_size: f(6), max_size: f(7),
            min_gap: f(8), density: f(9),
        };
        spec.cellular = CellularParams {
            cols: n(3), rows: n(4), cell_size: f(10), fill_min: f(3), fill_max: f(5),
            smoothing_steps: n(5) % 50, birth: (n(6) % 11) as u32, survival: (n(7) % 11) as u32,
            apron: f(6) * 2.0,
        };
        spec.corridors = CorridorsParams {
            cols: n(2), rows: n(3), corridor_width: f(1), wall_thickness: f(11),
            branches: n(4) % 100, branch_length: n(5),
        };
        spec.beacons = n(6);
        spec.min_coverage = f(4);
        match generate(&spec, seed) {
            Ok(s) => {
                let back = parse_scenario(&scenario_toml(&s), &s.path);
                prop_assert!(back.is_ok_and(|b| b == s));
            }
            Err(e) => {
                let prefix = format!("world `{}", spec.family);
                let text = e.to_string();
                prop_assert!(text.starts_with(&prefix), "{}", text);
            }
        }
    }
}

/// Each solvability check refuses what it guards: a blocked start, a blocked goal, a walled-off
/// goal, and a start that reaches too little of the free space.
#[test]
fn the_solvability_checks_refuse_what_they_guard() {
    let open = parse_scenario(
        "[start]\nx = 1.0\ny = 1.0\n[goal]\nx = 8.0\ny = 5.0\n",
        Path::new("t.toml"),
    )
    .unwrap();
    assert!(check_solvable(&open, 1.0, 0.0).is_ok());
    let mut s = open.clone();
    s.obstacles.push(Square::new(1.0, 1.3, 0.5));
    assert!(
        check_solvable(&s, 0.0, 0.0)
            .unwrap_err()
            .contains("start disk")
    );
    let mut s = open.clone();
    s.obstacles.push(Square::new(8.0, 5.0, 0.5));
    assert!(
        check_solvable(&s, 0.0, 0.0)
            .unwrap_err()
            .contains("goal disk")
    );
    // A wall across the arena at x = 5: the goal beyond it, half the free space unreachable.
    let mut walled = open.clone();
    walled.obstacles = (0..10)
        .map(|k| Square::new(5.0, 0.5 + f64::from(k), 1.0))
        .collect();
    let e = check_solvable(&walled, 0.0, 0.0).unwrap_err();
    assert!(e.contains("not reachable"), "{e}");
    walled.goal = Some(Goal {
        x: 2.0,
        y: 8.0,
        tolerance: GOAL_TOLERANCE,
    });
    assert!(check_solvable(&walled, 0.4, 0.0).is_ok());
    let e = check_solvable(&walled, 0.6, 0.0).unwrap_err();
    assert!(e.contains("less than min_coverage = 0.6"), "{e}");
    // A wall across at x = 5 with one gap, 0.05 m wider than the robot, centred at y = 5:
    // passable, but not with the clearance a family asks for.
    let wide = 2.0 * open.robot.radius + 0.05;
    let mut gap = open.clone();
    gap.obstacles = (0..20)
        .filter(|k| *k != 9 && *k != 10)
        .map(|k| Square::new(5.0, 0.25 + 0.5 * f64::from(k), 0.5))
        .chain([-1.0, 1.0].map(|side| Square::new(5.0, 5.0 + side * (wide / 2.0 + 0.25), 0.5)))
        .collect();
    assert!(check_solvable(&gap, 0.0, 0.0).is_ok());
    let e = check_solvable(&gap, 0.0, 0.1).unwrap_err();
    assert!(e.contains("clearance = 0.1"), "{e}");
    let mut crowded = open;
    crowded.obstacles = vec![Square::new(5.0, 5.0, 0.1); MAX_OBSTACLES + 1];
    assert!(
        check_solvable(&crowded, 0.0, 0.0)
            .unwrap_err()
            .contains("2049 obstacles")
    );
}

/// `min_coverage = 1` admits only worlds whose every free cell the start reaches: cellular draws
/// with enclosed pockets are drawn again.
#[test]
fn min_coverage_refuses_pockets() {
    let mut spec = WorldSpec::new(Family::Cellular);
    spec.min_coverage = 1.0;
    let mut pockets = 0;
    for seed in 0..20 {
        let s = world(&spec, seed);
        assert_eq!(
            FreeSpace::new(&s).count(crate::free_space::FREE),
            0,
            "seed {seed}"
        );
        let lax = world(&WorldSpec::new(Family::Cellular), seed);
        if FreeSpace::new(&lax).count(crate::free_space::FREE) > 0 {
            pockets += 1;
        }
    }
    assert!(
        pockets > 0,
        "no default world has a pocket: the test shows nothing"
    );
}

/// Whether the segment from `a` to `b` meets the square (the slab test; touching counts).
fn blocks(o: &Square, a: (f64, f64), b: (f64, f64)) -> bool {
    let (lo, hi) = (o.min(), o.max());
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, d, l, h) in [(a.0, b.0 - a.0, lo.0, hi.0), (a.1, b.1 - a.1, lo.1, hi.1)] {
        if d.abs() < 1e-15 {
            if p < l || p > h {
                return false;
            }
        } else {
            let (mut u, mut v) = ((l - p) / d, (h - p) / d);
            if u > v {
                std::mem::swap(&mut u, &mut v);
            }
            t0 = t0.max(u);
            t1 = t1.min(v);
            if t0 > t1 {
                return false;
            }
        }
    }
    true
}

/// Fraction of reachable sample points (every 0.25 m) that see a beacon in range.
fn beacon_cover(s: &Scenario) -> f64 {
    let space = FreeSpace::new(s);
    let (mut seen, mut all) = (0, 0);
    let range = s.sensors.beacon_range_max;
    let mut y = 0.125;
    while y < s.arena_height {
        let mut x = 0.125;
        while x < s.arena_width {
            if space.is_reachable(x, y) {
                all += 1;
                if s.beacons.iter().any(|b| {
                    let d = ((b.x - x).powi(2) + (b.y - y).powi(2)).sqrt();
                    d <= range && !s.obstacles.iter().any(|o| blocks(o, (x, y), (b.x, b.y)))
                }) {
                    seen += 1;
                }
            }
            x += 0.25;
        }
        y += 0.25;
    }
    f64::from(seen) / f64::from(all.max(1))
}

/// The beacons are placed where an estimator can use them: from most of the reachable space one
/// is in range with no square across the line (exactly, against the squares), even in a maze,
/// where walls hide most of the world from any one place.
#[test]
fn beacons_are_in_sight_from_most_of_the_world() {
    for (family, least) in [
        (Family::Maze, 0.55),
        (Family::Rooms, 0.95),
        (Family::Clutter, 0.95),
        (Family::Cellular, 0.95),
        (Family::Corridors, 0.7),
    ] {
        let spec = WorldSpec::new(family);
        for seed in 0..20 {
            let cover = beacon_cover(&world(&spec, seed));
            assert!(cover >= least, "{family} seed {seed}: {cover:.2} in sight");
        }
    }
}
