//! Two robots on one machine (two namespaces, two `mole up`), each running EKF-SLAM on the ring
//! of scenarios/slam_loop.toml in a world of its own, exchange their landmark maps and fuse the
//! other's by covariance intersection (`mole-localization --peer`), against the same robots
//! alone.
//!
//! Lockstep, because each stack is then the same run whatever the load of the machine (two
//! stacks share two cores here): robot A alone is bit for bit the run robot A makes with its
//! peer up to the first fusion, so the difference is the fusion's. A robot reads the newest map
//! its peer offers and never waits for it, so which map a round fuses depends on the two
//! stacks' pace: left free, one pair's fused result swung 5× between two runs of the test. So
//! the fused stacks start held (`--paused`) and an operator steps them in turns of one fusion
//! period, A then B: each round fuses the map of a known step, and the test is the same run
//! every time.

use mole_integration_tests::*;
use mole_monitor::{SlamSummary, mean_nees_interval};
use mole_runtime::ClockMode;
use mole_types::{EndReason, EstimatorKind, PACE_STEP, PlannerKind, Truth};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Steps allowed: frontier exploration finishes the ring in about 5,100 (seed 1).
const TICKS: &str = "6000";
/// Steps between two fusions: 1 s at 100 Hz, the default.
const FUSE_EVERY: &str = "100";
/// Robot A's and robot B's seeds, one pair per sample: the same ring and start, independent
/// noise.
const SEED_PAIRS: [[&str; 2]; 8] = [
    ["1", "2"],
    ["3", "4"],
    ["5", "6"],
    ["7", "8"],
    ["9", "10"],
    ["11", "12"],
    ["13", "14"],
    ["15", "16"],
];

/// One robot's run: its summary and what its localization logged.
struct Run {
    summary: Summary,
    localization_log: String,
}

impl Run {
    /// The landmark map's score; the run ended by itself and mapped every beacon.
    fn slam(&self) -> &SlamSummary {
        let s = &self.summary;
        assert!(
            [
                EndReason::ExplorationComplete.name(),
                EndReason::Ticks.name()
            ]
            .contains(&s.exit_reason.as_str()),
            "{s:#?}"
        );
        let slam = s.slam.as_ref().expect("a slam section for EKF-SLAM");
        assert_eq!(slam.beacons_mapped, 24, "{slam:#?}");
        slam
    }

    fn rmse(&self) -> f64 {
        self.slam().landmark_rmse_m.expect("landmarks matched")
    }

    fn nees(&self) -> f64 {
        self.slam().landmark_nees.expect("a landmark NEES")
    }

    /// A total of the peer fusion (`rounds`, `fused`, `kept`, `unmapped`, `refused`) from the
    /// line localization logs at the end of a run with a peer.
    fn fusion(&self, field: &str) -> u64 {
        let plain = without_colours(&self.localization_log);
        let line = plain
            .lines()
            .rfind(|l| l.contains("peer fusion totals"))
            .unwrap_or_else(|| panic!("no fusion totals logged:\n{plain}"));
        let needle = format!("{field}=");
        line.split_whitespace()
            .find_map(|word| word.strip_prefix(&needle)?.parse().ok())
            .unwrap_or_else(|| panic!("no {field} in `{line}`"))
    }
}

/// A directory of launch files, removed when the test ends, however it ends.
struct LaunchDir(PathBuf);

impl LaunchDir {
    fn new() -> LaunchDir {
        let dir = std::env::temp_dir().join(unique_namespace("two-robots-launch"));
        std::fs::create_dir_all(&dir).expect("create the launch directory");
        LaunchDir(dir)
    }

    /// launch/stacks/lockstep.toml with `--peer peer` for localization, as `name`.
    fn with_peer(&self, name: &str, peer: &str) -> PathBuf {
        let stock = std::fs::read_to_string(workspace().join("launch/stacks/lockstep.toml"))
            .expect("read launch/stacks/lockstep.toml");
        let command = "command = \"mole-localization\"";
        assert!(stock.contains(command), "{stock}");
        let args = format!(
            "{command}\nargs = [\"--peer\", \"{peer}\", \"--fuse-every\", \"{FUSE_EVERY}\"]"
        );
        let path = self.0.join(name);
        std::fs::write(&path, stock.replace(command, &args)).expect("write a launch file");
        path
    }
}

impl Drop for LaunchDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Starts `mole up` with `launch` for the robot with `seed`, in `namespace`, on the ring; held
/// after step 0 when `paused`.
fn start(namespace: &str, launch: &Path, seed: &str, paused: bool) -> Stack {
    let mut args = vec![
        launch.to_str().expect("a UTF-8 path"),
        "--seed",
        seed,
        "--scenario",
        "scenarios/slam_loop.toml",
        "--planner",
        PlannerKind::Frontier.name(),
        "--estimator",
        EstimatorKind::EkfSlam.name(),
        "--ticks",
        TICKS,
    ];
    if paused {
        args.push("--paused");
    }
    Stack::start_in(namespace, &args)
}

/// Steps the two held stacks in turns of one fusion period until both runs ended, the robot
/// that goes first swapping every period. A turn is over when its planner has published the
/// status of the turn's last step, which comes after localization published its map of that
/// step: so the robot that goes first fuses at step k its peer's map of step k − period, and
/// the other the first's map of step k. With A always first, A fused only maps a period old,
/// which its own 100 steps since had mostly made redundant (CI kept A's map in 7 of 8 pairs).
fn step_in_turns(stacks: &[Stack; 2]) {
    let period: u32 = FUSE_EVERY.parse().expect("a number");
    let mut operators = stacks
        .each_ref()
        .map(|s| Operator::join(s, ClockMode::Lockstep));
    let ended = |o: &Operator| o.truth.latest().is_some_and(Truth::is_end);
    let mut at = [0_u64; 2];
    let mut turn = 0;
    while !operators.iter().all(ended) {
        let order = if turn % 2 == 0 { [0, 1] } else { [1, 0] };
        turn += 1;
        for i in order {
            let operator = &mut operators[i];
            if ended(operator) {
                continue;
            }
            let goal = at[i] + u64::from(period);
            operator.send_pace(PACE_STEP, period);
            operator.follow_until("a turn", Duration::from_secs(300), |o| {
                ended(o) || o.status.tick().is_some_and(|t| t >= goal)
            });
            at[i] = goal;
        }
    }
}

/// Waits for `stack` to end by itself, then reads its run; none of its processes is left.
fn finish(stack: Stack) -> Run {
    let namespace = stack.namespace.clone();
    let keep = stack.out.with_extension("kept");
    let output = stack.wait_and_copy(&keep, Duration::from_secs(900));
    let logs = logs(&keep);
    let run = Run {
        summary: summary(&keep),
        localization_log: std::fs::read_to_string(keep.join("logs/localization.log"))
            .unwrap_or_default(),
    };
    let _ = std::fs::remove_dir_all(&keep);
    assert!(
        output.status.success(),
        "{namespace}: {}\n{logs}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert_eq!(processes_of(&namespace), Vec::<u32>::new(), "{namespace}");
    run
}

/// Robots A and B alone, then together, fusing each other's map every second by CI. One
/// stack run is one sample: after the first fusion a robot's estimate, and so its planner's map
/// and its path, differ from its run alone, and EKF-SLAM alone on this ring spreads widely from
/// seed to seed. So each robot is scored over the [`SEED_PAIRS`] (each pair alone, then
/// together):
///
/// (a) each robot's fused mean landmark NEES, averaged over the pairs, is below the upper end
///     of the 95% interval a consistent map's falls in over that many runs, χ²₂ᵣ(0.975)/R
///     (R runs; a run's mean NEES has variance at most that of one χ²(2) whatever the
///     correlation of its landmarks' errors, so this is the wide end; naive information-sum
///     fusion, which counts the other's information again at every round, put it at 2.2e19);
/// (b) fusion happened: each robot had rounds with a new peer map and intersected the landmarks
///     both had (fused, or kept where CI's optimum was its own estimate), and a robot's map
///     changed in most pairs.
///
/// Measured: fused NEES A 1.59, B 1.72 (alone 1.61 and 2.07), against an upper end of 3.61; a
/// map changed in 6 of the 8 pairs. The landmark RMSE is printed, not claimed: averaged over
/// the pairs it was A 0.0231 m fused against 0.0218 m alone, B 0.0237 against 0.0237 m. Of the
/// nine robot runs whose map fusion changed, four ended better and three worse; CI is
/// consistent only when what it fuses is, and where one robot's map is over-confident (seeds 3
/// and 4: B's NEES 4.3) the other takes in its error (A 0.0101 → 0.0237 m). With A always
/// stepping first, A fused only maps a period old and kept its own in 7 of 8 pairs, so the
/// turns alternate ([`step_in_turns`]). The peer's covariance taken at a quarter of what it is
/// puts the fused NEES at 7.3 (A) and 7.0 (B), above the upper end: the test fails (and the RMSE
/// falls to 0.014 m, which is why RMSE alone cannot judge a fusion).
///
/// The claims over 50 seeded runs of the filter alone, where fusing lowers both robots' RMSE,
/// are in processes/localization/tests/slam_two_robots.rs.
#[test]
fn two_robots_fusing_their_maps_by_ci_stay_consistent() {
    let _serial = serial();
    let launch = LaunchDir::new();
    let stock = workspace().join("launch/stacks/lockstep.toml");
    let runs = SEED_PAIRS.len();
    let (mut rmse_alone, mut rmse_fused, mut nees_fused) = ([0.0; 2], [0.0; 2], [0.0; 2]);
    let mut pairs_changed = 0;
    for seeds in SEED_PAIRS {
        // Alone: both at once (lockstep: each the same run whatever the load).
        let alone_stacks = [0, 1].map(|r| {
            let namespace = unique_namespace(["two_a_alone", "two_b_alone"][r]);
            start(&namespace, &stock, seeds[r], false)
        });
        let alone = alone_stacks.map(finish);
        // Together: each robot's localization has the other's namespace as its peer.
        let namespaces = [unique_namespace("two_a"), unique_namespace("two_b")];
        let fused_stacks = [0, 1].map(|r| {
            let file = launch.with_peer(["a.toml", "b.toml"][r], &namespaces[1 - r]);
            start(&namespaces[r], &file, seeds[r], true)
        });
        step_in_turns(&fused_stacks);
        let fused = fused_stacks.map(finish);
        for (r, robot) in ["A", "B"].iter().enumerate() {
            let (f, a) = (&fused[r], &alone[r]);
            println!(
                "seeds {seeds:?} robot {robot}: landmark RMSE {:.4} m fused, {:.4} m alone; NEES \
                 {:.3} fused, {:.3} alone; fusion rounds {}, fused {}, kept {}, unmapped {}, \
                 refused {}",
                f.rmse(),
                a.rmse(),
                f.nees(),
                a.nees(),
                f.fusion("rounds"),
                f.fusion("fused"),
                f.fusion("kept"),
                f.fusion("unmapped"),
                f.fusion("refused"),
            );
            assert!(
                f.fusion("rounds") > 0,
                "seeds {seeds:?} robot {robot}: no round fused"
            );
            assert!(
                f.fusion("fused") + f.fusion("kept") > 0,
                "seeds {seeds:?} robot {robot}: no landmark both maps had"
            );
            rmse_alone[r] += a.rmse() / runs as f64;
            rmse_fused[r] += f.rmse() / runs as f64;
            nees_fused[r] += f.nees() / runs as f64;
        }
        if fused.iter().any(|f| f.fusion("fused") > 0) {
            pairs_changed += 1;
        } else {
            println!("seeds {seeds:?}: neither robot's map was changed by the other's");
        }
    }
    println!("pairs in which a robot's map changed: {pairs_changed} of {runs}");
    assert!(
        2 * pairs_changed > runs,
        "a robot's map changed in only {pairs_changed} of {runs} pairs"
    );
    let [_, nees_upper] = mean_nees_interval(2, runs as u32).expect("runs");
    let mut broken = Vec::new();
    for (r, robot) in ["A", "B"].iter().enumerate() {
        println!(
            "robot {robot}, mean of {runs} runs: landmark RMSE {:.4} m fused, {:.4} m alone; \
             NEES {:.3} fused (95% upper end {nees_upper:.3})",
            rmse_fused[r], rmse_alone[r], nees_fused[r]
        );
        if nees_fused[r] >= nees_upper {
            broken.push(format!(
                "robot {robot} fused: mean landmark NEES {} above {nees_upper}",
                nees_fused[r]
            ));
        }
    }
    assert!(broken.is_empty(), "{}", broken.join("\n"));
}
