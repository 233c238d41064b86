//! GraphSLAM (Thrun et al. 2005, ch. 11; Grisetti et al. 2010): the optimum of a noise-free
//! graph is the truth, smoothing beats dead reckoning and an online EKF-SLAM on a loop, the
//! factor Jacobians match finite differences, the landmark marginals match linear error
//! propagation, incremental solves reach the batch optimum, and bad input is refused and
//! counted.

mod graph_slam_support;

use graph_slam_support::{Drive, default_noise, odom, position_rmse, reading, simulate};
use mole_localization::graph_slam::factors::{ObservationFactor, OdometryFactor};
use mole_localization::graph_slam::{
    GraphCapacity, GraphError, GraphSlamConfig, PoseGraph, Termination,
};
use mole_localization::models::{add_slide, unicycle_g};
use mole_localization::slam::{EkfSlam, SlamConfig};
use mole_types::{Pose2, wrap_angle};
use nalgebra::{Matrix2, Matrix2x3, Matrix3, Vector2, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// One lap of 120 steps at 10 Hz around a 4 m circle among 10 beacons seen within 4 m.
const LOOP: Drive = Drive {
    radius: 4.0,
    steps_per_lap: 120,
    laps: 1,
    dt: 0.1,
    beacons: 10,
    range_max: 4.0,
};

/// The noise-free optimum, reached from an initial guess perturbed by ~0.3 m and ~0.2 rad,
/// is the true trajectory and map to 1e-9.
#[test]
fn noise_free_optimum_is_the_truth_from_a_perturbed_guess() {
    let noise = default_noise();
    let sim = simulate(&LOOP, &noise, None);
    let mut graph = sim.graph(&noise);
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for (k, t) in sim.truth.iter().enumerate() {
        let kick = Vector3::new(
            rng.random_range(-0.3..0.3),
            rng.random_range(-0.3..0.3),
            rng.random_range(-0.2..0.2),
        );
        graph.set_pose(k, t + kick).unwrap();
    }
    for (j, &id) in graph.landmark_ids().to_vec().iter().enumerate() {
        let kick = Vector2::new(rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3));
        graph
            .set_landmark(j, sim.beacons[id as usize] + kick)
            .unwrap();
    }
    let solution = graph.optimize(50).unwrap();
    let report = solution.report;
    println!("noise-free: {report:?}");
    assert_eq!(report.termination, Termination::Converged, "{report:?}");
    assert!(report.final_cost < 1e-12, "{report:?}");
    for (k, (p, t)) in solution.poses.iter().zip(&sim.truth).enumerate() {
        let d = Vector3::new(p[0] - t[0], p[1] - t[1], wrap_angle(p[2] - t[2]));
        assert!(d.amax() < 1e-9, "pose {k}: {p:?} vs truth {t:?}");
    }
    assert_eq!(solution.landmarks.len(), LOOP.beacons);
    for (m, &id) in solution.landmarks.iter().zip(solution.landmark_ids) {
        let t = sim.beacons[id as usize];
        assert!((m - t).amax() < 1e-9, "beacon {id}: {m:?} vs truth {t:?}");
    }
}

/// Over eight seeded noisy laps whose end revisits the beacons seen at the start, the smoothed
/// trajectory's RMSE is below the dead-reckoned chain's and below an online EKF-SLAM's.
#[test]
fn smoothing_beats_dead_reckoning_and_online_ekf_slam_on_a_loop() {
    let noise = default_noise();
    let seeds = 8;
    let (mut dead_reckoning, mut filter, mut smoothed) = (0.0, 0.0, 0.0);
    for seed in 0..seeds {
        let sim = simulate(&LOOP, &noise, Some(seed));
        let first: Vec<u32> = sim.readings[0].iter().map(|r| r.id).collect();
        let last = sim.readings.last().unwrap();
        assert!(
            last.iter().any(|r| first.contains(&r.id)),
            "the lap must close the loop through a beacon seen at both ends"
        );
        // The online filter: the crate's EKF-SLAM, started with the graph's prior σ.
        let mut ekf = EkfSlam::new(
            sim.start,
            Matrix3::from_diagonal_element(1e-6),
            noise,
            sim.beacons.len(),
            SlamConfig::default(),
        );
        let as_vector = |p: Pose2| Vector3::new(p.x, p.y, p.theta);
        let mut online = vec![as_vector(ekf.pose())];
        ekf.correct(&sim.readings[0]);
        for (u, readings) in sim.odometry.iter().zip(&sim.readings[1..]) {
            ekf.predict(u.v, u.omega, u.dt).expect("plausible odometry");
            ekf.correct(readings);
            online.push(as_vector(ekf.pose()));
        }
        let mut graph = sim.graph(&noise);
        let chain = graph.poses().to_vec();
        let solution = graph.optimize(30).unwrap();
        assert_eq!(solution.report.termination, Termination::Converged);
        let (a, b, c) = (
            position_rmse(&chain, &sim.truth),
            position_rmse(&online, &sim.truth),
            position_rmse(solution.poses, &sim.truth),
        );
        println!(
            "seed {seed}: RMSE dead reckoning {a:.4} m, EKF-SLAM {b:.4} m, GraphSLAM {c:.4} m \
             ({} iterations)",
            solution.report.iterations
        );
        assert!(c < a, "seed {seed}: smoothed {c} vs dead reckoning {a}");
        dead_reckoning += a / seeds as f64;
        filter += b / seeds as f64;
        smoothed += c / seeds as f64;
    }
    println!(
        "mean RMSE over {seeds} seeds: dead reckoning {dead_reckoning:.4} m, EKF-SLAM \
         {filter:.4} m, GraphSLAM {smoothed:.4} m"
    );
    assert!(
        smoothed < filter,
        "GraphSLAM {smoothed} vs EKF-SLAM {filter}"
    );
    assert!(
        smoothed < dead_reckoning,
        "GraphSLAM {smoothed} vs dead reckoning {dead_reckoning}"
    );
}

/// Central difference of `f` along `x[j]`, with the rows in `angles` wrapped.
fn central_diff<const N: usize, const M: usize>(
    f: impl Fn(&nalgebra::SVector<f64, N>) -> nalgebra::SVector<f64, M>,
    x: &nalgebra::SVector<f64, N>,
    j: usize,
    angles: &[usize],
) -> nalgebra::SVector<f64, M> {
    let h = 1e-6;
    let (mut plus, mut minus) = (*x, *x);
    plus[j] += h;
    minus[j] -= h;
    let mut d = f(&plus) - f(&minus);
    for &r in angles {
        d[r] = wrap_angle(d[r]);
    }
    d / (2.0 * h)
}

/// Asserts two Jacobians agree to 1e-6 relative.
fn assert_jacobian<const R: usize, const C: usize>(
    name: &str,
    analytic: &nalgebra::SMatrix<f64, R, C>,
    numeric: &nalgebra::SMatrix<f64, R, C>,
) {
    for i in 0..R {
        for j in 0..C {
            let (a, n) = (analytic[(i, j)], numeric[(i, j)]);
            assert!(
                (a - n).abs() <= 1e-6 * (1.0 + a.abs().max(n.abs())),
                "{name}[{i},{j}]: analytic {a} vs finite difference {n}"
            );
        }
    }
}

/// The odometry and observation factors' analytic Jacobians match central differences of
/// their residuals at random, non-zero-residual points (so the frame-rotation term counts).
#[test]
fn factor_jacobians_match_finite_differences() {
    let noise = default_noise();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for _ in 0..200 {
        let mut random_pose = || {
            Vector3::new(
                rng.random_range(-5.0..5.0),
                rng.random_range(-5.0..5.0),
                rng.random_range(-3.1..3.1),
            )
        };
        let (x_a, x_b, pose) = (random_pose(), random_pose(), random_pose());
        let v = rng.random_range(-1.0..1.0);
        let omega = if rng.random_bool(0.2) {
            0.0
        } else {
            rng.random_range(-2.0..2.0)
        };
        let dt = rng.random_range(0.01..0.5);
        // Half the factors with a slide along a wall (its Jacobians are those without).
        let sideways = if rng.random_bool(0.5) {
            Vector2::new(rng.random_range(-0.1..0.1), rng.random_range(-0.1..0.1))
        } else {
            Vector2::zeros()
        };
        let factor = OdometryFactor::new(&noise, v, omega, dt)
            .unwrap()
            .with_slide(&sideways);
        // The pose the slide reaches, where the wheels' arc ends and then slides, has no error.
        let mut reached = unicycle_g(&x_a, v, omega, dt);
        add_slide(&mut reached, None, &sideways);
        assert!(factor.residual(&x_a, &reached).norm() < 1e-12);
        let (j_a, j_b) = factor.jacobians(&x_a, &x_b);
        let mut fd_a = Matrix3::zeros();
        let mut fd_b = Matrix3::zeros();
        for j in 0..3 {
            fd_a.set_column(
                j,
                &central_diff(|x| factor.residual(x, &x_b), &x_a, j, &[2]),
            );
            fd_b.set_column(
                j,
                &central_diff(|x| factor.residual(&x_a, x), &x_b, j, &[2]),
            );
        }
        assert_jacobian("odometry ∂e/∂x_a", &j_a, &fd_a);
        assert_jacobian("odometry ∂e/∂x_b", &j_b, &fd_b);

        let landmark = Vector2::new(rng.random_range(-5.0..5.0), rng.random_range(-5.0..5.0));
        if (landmark - pose.xy()).norm() < 0.2 {
            continue;
        }
        let observation = ObservationFactor {
            pose: 0,
            landmark: 0,
            range: rng.random_range(0.5..5.0),
            bearing: rng.random_range(-3.1..3.1),
        };
        let (e, j_pose) = observation.linearise(&pose, &landmark).unwrap();
        assert_eq!(Some(e), observation.residual(&pose, &landmark));
        let j_landmark = -j_pose.fixed_columns::<2>(0);
        let mut fd_pose = Matrix2x3::zeros();
        let mut fd_landmark = Matrix2::zeros();
        for j in 0..3 {
            let e = |x: &Vector3<f64>| observation.residual(x, &landmark).unwrap();
            fd_pose.set_column(j, &central_diff(e, &pose, j, &[1]));
        }
        for j in 0..2 {
            let e = |m: &Vector2<f64>| observation.residual(&pose, m).unwrap();
            fd_landmark.set_column(j, &central_diff(e, &landmark, j, &[1]));
        }
        assert_jacobian("observation ∂e/∂x", &j_pose, &fd_pose);
        assert_jacobian("observation ∂e/∂m", &j_landmark, &fd_landmark);
    }
}

/// A graph of the anchored first pose alone, with room for `landmarks` beacons read once each.
fn one_pose_graph(start: Pose2, config: GraphSlamConfig, landmarks: usize) -> PoseGraph {
    let capacity = GraphCapacity {
        poses: 1,
        landmarks,
        observations: landmarks,
    };
    PoseGraph::new(start, config, capacity)
}

/// ∂m/∂x (A) and ∂m/∂z (B) of the inverse measurement model m = (x, y) + r·(cos, sin)(θ + b) at
/// pose `start` for a reading (`range`, `bearing`).
fn inverse_measurement_jacobians(
    start: Pose2,
    range: f64,
    bearing: f64,
) -> (Matrix2x3<f64>, Matrix2<f64>) {
    let (s, c) = (start.theta + bearing).sin_cos();
    let a = Matrix2x3::new(1.0, 0.0, -range * s, 0.0, 1.0, range * c);
    let b = Matrix2::new(c, -range * s, s, range * c);
    (a, b)
}

/// A beacon read once from the anchored first pose has the marginal covariance of linear error
/// propagation through the inverse measurement model: A Σ₀ Aᵀ + B Q Bᵀ.
#[test]
fn landmark_covariance_matches_linear_propagation() {
    let noise = default_noise();
    let start = Pose2::new(1.0, -2.0, 0.4);
    let config = GraphSlamConfig::new(noise);
    let mut graph = one_pose_graph(start, config, 1);
    let (range, bearing) = (3.0, 0.7);
    graph
        .add_observation(0, &reading(4, range, bearing))
        .unwrap();
    graph.optimize(10).unwrap();
    let mut covariances = Vec::new();
    graph.landmark_covariances(&mut covariances).unwrap();
    let (a, b) = inverse_measurement_jacobians(start, range, bearing);
    let sigma0 = Matrix3::from_diagonal(&Vector3::from(config.prior_std.map(|s| s * s)));
    let expected = a * sigma0 * a.transpose() + b * noise.q_beacon() * b.transpose();
    assert_eq!(covariances.len(), 1);
    let got = covariances[0];
    println!("landmark covariance {got} expected {expected}");
    assert!(
        (got - expected).amax() < 1e-9 * expected.amax(),
        "{got} vs {expected}"
    );
}

/// Two beacons read once each from the anchored first pose share its error: the joint
/// covariance of linear propagation has P₁₂ = A₁ Σ₀ A₂ᵀ, and the map's mean-NEES degrees of
/// freedom the graph gives from the landmark block of H⁻¹ are those of that joint covariance.
#[test]
fn landmark_nees_dof_is_that_of_the_joint_covariance() {
    let noise = default_noise();
    let start = Pose2::new(1.0, -2.0, 0.4);
    // An uncertain anchor, so that the error the two share is not negligible.
    let mut config = GraphSlamConfig::new(noise);
    config.prior_std = [0.3, 0.2, 0.1];
    let mut graph = one_pose_graph(start, config, 2);
    let readings = [(3.0, 0.7), (2.0, -1.2)];
    for (id, &(range, bearing)) in readings.iter().enumerate() {
        graph
            .add_observation(0, &reading(id as u32, range, bearing))
            .unwrap();
    }
    graph.optimize(10).unwrap();
    let mut covariances = Vec::new();
    graph.landmark_covariances(&mut covariances).unwrap();
    let sigma0 = Matrix3::from_diagonal(&Vector3::from(config.prior_std.map(|s| s * s)));
    let jacobians =
        readings.map(|(range, bearing)| inverse_measurement_jacobians(start, range, bearing));
    let block = |i: usize, j: usize| {
        let (ai, bi) = jacobians[i];
        let shared = ai * sigma0 * jacobians[j].0.transpose();
        if i == j {
            shared + bi * noise.q_beacon() * bi.transpose()
        } else {
            shared
        }
    };
    let expected = mole_localization::slam::mean_nees_dof(2, block);
    let got = graph.landmark_nees_dof();
    println!("ν {got} expected {expected}");
    assert!(expected > 2.0 && expected < 3.5, "{expected}");
    assert!((got - expected).abs() < 1e-9, "{got} vs {expected}");
}

/// Compiles only for types a background solver thread can own.
fn owned_by_a_solver_thread<T: Send + 'static>(_: &T) {}

/// A graph grown step by step with a few LM iterations after every tenth step ends at the same
/// optimum as one batch solve, a call on an unchanged graph reuses the symbolic analysis, and
/// the graph can be moved to the solver thread that drives it.
#[test]
fn incremental_solves_reach_the_batch_optimum() {
    let noise = default_noise();
    let sim = simulate(&LOOP, &noise, Some(3));
    let mut batch = sim.graph(&noise);
    let batch_poses = batch.optimize(50).unwrap().poses.to_vec();

    let capacity = GraphCapacity {
        poses: sim.truth.len(),
        landmarks: sim.beacons.len(),
        observations: sim.reading_count(),
    };
    let mut graph = PoseGraph::new(sim.start, GraphSlamConfig::new(noise), capacity);
    owned_by_a_solver_thread(&graph);
    let mut solves = 0;
    for (k, readings) in sim.readings.iter().enumerate() {
        if k > 0 {
            assert_eq!(graph.add_pose(&sim.odometry[k - 1]), Ok(k));
        }
        for r in readings {
            graph.add_observation(k, r).unwrap();
        }
        if k % 10 == 0 {
            let report = graph.optimize(3).unwrap().report;
            assert!(report.reanalysed, "step {k}: the graph grew");
            solves += 1;
        }
    }
    let report = graph.optimize(50).unwrap().report;
    assert_eq!(report.termination, Termination::Converged);
    let again = graph.optimize(50).unwrap().report;
    assert!(!again.reanalysed, "nothing was added: {again:?}");
    let worst = graph
        .poses()
        .iter()
        .zip(&batch_poses)
        .map(|(a, b)| (a - b).xy().amax())
        .fold(0.0, f64::max);
    println!("{solves} incremental solves; largest difference to batch {worst:e} m");
    assert!(worst < 1e-6, "incremental vs batch: {worst}");
}

/// NaN or absurd odometry and readings, and readings of unknown poses, are refused with an
/// error, counted, and leave the graph as it was; the graph still solves.
#[test]
fn bad_input_is_refused_and_counted() {
    let noise = default_noise();
    let capacity = GraphCapacity {
        poses: 4,
        landmarks: 2,
        observations: 8,
    };
    let mut graph = PoseGraph::new(
        Pose2::new(0.0, 0.0, 0.0),
        GraphSlamConfig::new(noise),
        capacity,
    );
    assert_eq!(graph.add_pose(&odom(0.5, 0.1, 0.1)), Ok(1));
    graph.add_observation(1, &reading(0, 2.0, 0.3)).unwrap();
    let bad_odometry = [
        (odom(f64::NAN, 0.0, 0.1), GraphError::NotFinite("odometry")),
        (
            odom(0.5, f64::INFINITY, 0.1),
            GraphError::NotFinite("odometry"),
        ),
        (odom(0.5, 0.0, f64::NAN), GraphError::NotFinite("odometry")),
        (odom(1e6, 0.0, 0.1), GraphError::OutOfRange("speed")),
        (odom(0.5, -1e3, 0.1), GraphError::OutOfRange("turn rate")),
        (odom(0.5, 0.0, -0.1), GraphError::OutOfRange("dt")),
        (odom(0.5, 0.0, 1e9), GraphError::OutOfRange("dt")),
    ];
    for (i, (o, expected)) in bad_odometry.iter().enumerate() {
        assert_eq!(graph.add_pose(o), Err(*expected), "{o:?}");
        assert_eq!(graph.refused().odometry, i as u64 + 1);
    }
    let bad_readings = [
        (
            1,
            reading(0, f64::NAN, 0.0),
            GraphError::NotFinite("reading"),
        ),
        (
            1,
            reading(0, 1.0, f64::NAN),
            GraphError::NotFinite("reading"),
        ),
        (
            1,
            reading(1, f64::INFINITY, 0.0),
            GraphError::NotFinite("reading"),
        ),
        (1, reading(1, -1.0, 0.0), GraphError::OutOfRange("range")),
        (1, reading(1, 0.0, 0.0), GraphError::OutOfRange("range")),
        (1, reading(1, 1e7, 0.0), GraphError::OutOfRange("range")),
        (2, reading(1, 1.0, 0.0), GraphError::UnknownPose(2)),
        (
            usize::MAX,
            reading(1, 1.0, 0.0),
            GraphError::UnknownPose(usize::MAX),
        ),
    ];
    for (i, (pose, r, expected)) in bad_readings.iter().enumerate() {
        assert_eq!(graph.add_observation(*pose, r), Err(*expected), "{r:?}");
        assert_eq!(graph.refused().readings, i as u64 + 1);
    }
    assert_eq!(graph.poses().len(), 2);
    assert_eq!(graph.landmarks().len(), 1);
    assert_eq!(graph.observation_count(), 1);
    assert_eq!(
        graph.set_pose(0, Vector3::new(f64::NAN, 0.0, 0.0)),
        Err(GraphError::NotFinite("pose"))
    );
    let solution = graph.optimize(20).unwrap();
    assert!(solution.poses.iter().flatten().all(|x| x.is_finite()));
    assert_eq!(solution.report.termination, Termination::Converged);
}
