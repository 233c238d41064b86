//! EKF-SLAM against PythonRobotics' EKF-SLAM on one fixed input sequence with known
//! correspondences: our filter, run with their motion model and noise values, must end in their
//! state and covariance to 1e-9.
//!
//! How the reference numbers were made: the repository AtsushiSakai/PythonRobotics (commit
//! b38c510e083d69a5755d98d0680bd50f3d9a91fa), file SLAM/EKFSLAM/ekf_slam.py, was imported
//! unchanged by a small driver script (kept outside this repository) that ran under Python 3.11
//! with numpy 2.4 (matplotlib and scipy, imported but unused on this path, stubbed out). The
//! driver replaced only their association step
//! (`search_correspond_landmark_id`) by a lookup of the reading's true id, and then called their
//! `ekf_slam(xEst, PEst, u, z)` once per step for the 80 steps that [`inputs`] below builds
//! (the same formulas, with the same scalar libm sin/cos), starting from xEst = 0 and PEst = I
//! as their `main` does. It printed the final xEst and PEst with `repr` (17 significant digits),
//! which are the constants at the end of this file.
//!
//! Their conventions, and how the test reproduces them:
//! - Motion: an Euler step x += DT·v·cos θ, y += DT·v·sin θ, θ += DT·ω with DT = 0.1 s.
//! - Their Jacobian is G = I + Fxᵀ jF Fx with jF[0,2] = −DT·v·sin θ, jF[1,2] = DT·v·cos θ, but
//!   they propagate P ← Gᵀ P G + Fxᵀ Cx Fx (the transpose of Thrun's G P Gᵀ). Our filter does
//!   G P Gᵀ, so the reference model below hands it their G transposed; that reproduces their
//!   pose block Gᵀ Pₓₓ G and cross block Gᵀ Pₓₘ exactly.
//! - Process noise: Cx = diag(0.5 m, 0.5 m, 30°)² added to the pose block every step.
//! - Measurement noise: Cx[0:2, 0:2] = diag(0.25, 0.25) for (range, bearing).
//! - State layout: (x, y, yaw, then (x, y) per landmark in first-sight order) — ours too.
//! - New landmarks: mean x + r·(cos(θ + b), sin(θ + b)) (ours: the inverse observation model),
//!   covariance I with zero cross-covariance, then the ordinary update with the same reading:
//!   our `LandmarkInit::Prior { variance: 1.0 }` (Thrun's Table 10.2 with a finite prior).
//! - Their Jacobians are taken at the current estimate: our `Linearisation::Estimate` (the
//!   process uses the first estimates).
//! - Their covariance update is P ← (I − K H) P; ours is the Joseph form, equal for the optimal
//!   K up to rounding. They wrap the yaw once per step, we after each update: equal mod 2π.

use mole_localization::slam::{
    Correspondence, EkfSlam, LandmarkInit, Linearisation, MotionModel, SlamConfig,
};
use mole_types::{BeaconReading, Pose2};
use nalgebra::{Matrix2, Matrix3, Vector3};

/// Their DT (s).
const DT: f64 = 0.1;
/// Steps of the sequence.
const STEPS: usize = 80;
/// The landmark positions the readings are made from: their four RFIDs and one more.
const LANDMARKS: [(f64, f64); 5] = [
    (10.0, -2.0),
    (15.0, 10.0),
    (3.0, 15.0),
    (-5.0, 20.0),
    (8.0, 8.0),
];

/// PythonRobotics' EKF-SLAM motion model (see the module doc), test-only.
struct PythonRoboticsMotion;

impl MotionModel for PythonRoboticsMotion {
    fn g(&self, pose: &Vector3<f64>, v: f64, omega: f64, dt: f64) -> Vector3<f64> {
        Vector3::new(
            pose[0] + dt * pose[2].cos() * v,
            pose[1] + dt * pose[2].sin() * v,
            pose[2] + dt * omega,
        )
    }

    /// Their G transposed, so that our G P Gᵀ is their Gᵀ P G.
    fn jacobian_g(&self, pose: &Vector3<f64>, v: f64, _omega: f64, dt: f64) -> Matrix3<f64> {
        let theirs = Matrix3::new(
            1.0,
            0.0,
            -dt * v * pose[2].sin(),
            0.0,
            1.0,
            dt * v * pose[2].cos(),
            0.0,
            0.0,
            1.0,
        );
        theirs.transpose()
    }

    fn process_noise(&self, _: &Vector3<f64>, _: f64, _: f64, _: f64) -> Matrix3<f64> {
        cx()
    }
}

/// Their Cx = diag(0.5, 0.5, 30°)².
fn cx() -> Matrix3<f64> {
    Matrix3::from_diagonal(&Vector3::new(
        0.5f64.powi(2),
        0.5f64.powi(2),
        30f64.to_radians().powi(2),
    ))
}

/// Step k's control (v, ω) and readings: the controls vary smoothly; the readings are the exact
/// range and bearing from a "true" pose driven by biased controls (1.05·v, ω − 0.02), perturbed
/// by fixed sinusoids; landmark i is seen when (k + i) mod 4 ≠ 0, in reverse id order on odd k.
fn inputs() -> Vec<((f64, f64), Vec<BeaconReading>)> {
    let mut truth = [0.0f64; 3];
    (0..STEPS)
        .map(|k| {
            let kf = k as f64;
            let v = 1.0 + 0.3 * (0.4 * kf).sin();
            let w = 0.5 + 0.4 * (0.3 * kf).cos();
            let (vt, wt) = (1.05 * v, w - 0.02);
            truth = [
                truth[0] + DT * vt * truth[2].cos(),
                truth[1] + DT * vt * truth[2].sin(),
                truth[2] + DT * wt,
            ];
            let mut ids: Vec<usize> = (0..LANDMARKS.len()).filter(|i| (k + i) % 4 != 0).collect();
            if k % 2 == 1 {
                ids.reverse();
            }
            let readings = ids
                .into_iter()
                .map(|i| {
                    let fi = i as f64;
                    let (dx, dy) = (LANDMARKS[i].0 - truth[0], LANDMARKS[i].1 - truth[1]);
                    let b = dy.atan2(dx) - truth[2] + 0.02 * (2.3 * kf + 0.5 * fi).cos();
                    BeaconReading {
                        id: i as u32,
                        _pad: 0,
                        range: dx.hypot(dy) + 0.1 * (1.7 * kf + fi).sin(),
                        bearing: b.sin().atan2(b.cos()),
                    }
                })
                .collect();
            ((v, w), readings)
        })
        .collect()
}

/// Our EkfSlam, run with their model, noise and landmark initialisation on the fixed sequence,
/// ends in the state and covariance their code printed, to 1e-9.
#[test]
fn ekf_slam_matches_python_robotics_on_a_fixed_sequence() {
    let mut slam = EkfSlam::with_motion(
        PythonRoboticsMotion,
        Matrix2::new(0.25, 0.0, 0.0, 0.25),
        Pose2::new(0.0, 0.0, 0.0),
        Matrix3::identity(),
        LANDMARKS.len(),
        SlamConfig {
            correspondence: Correspondence::Known,
            outlier_probability: None,
            ..SlamConfig::default()
        },
    );
    slam.landmark_init = LandmarkInit::Prior { variance: 1.0 };
    slam.linearisation = Linearisation::Estimate;
    for ((v, w), readings) in inputs() {
        slam.predict(v, w, DT).expect("a plausible control");
        for r in &readings {
            slam.correct_reading(r).expect("every reading is used");
        }
    }
    let ids: Vec<u32> = slam.landmarks().map(|l| l.id).collect();
    assert_eq!(ids, [1, 2, 3, 4, 0], "first-sight order");
    let state = slam.state();
    let cov = slam.covariance();
    assert_eq!(state.len(), REFERENCE_STATE.len());
    let mut worst = 0.0f64;
    for (i, expected) in REFERENCE_STATE.iter().enumerate() {
        let d = if i == 2 {
            mole_types::wrap_angle(state[i] - expected)
        } else {
            state[i] - expected
        };
        assert!(
            d.abs() < 1e-9,
            "state[{i}]: ours {} theirs {expected}",
            state[i]
        );
        worst = worst.max(d.abs());
    }
    for (r, row) in REFERENCE_COVARIANCE.iter().enumerate() {
        for (c, expected) in row.iter().enumerate() {
            let d = (cov[(r, c)] - expected).abs();
            assert!(
                d < 1e-9,
                "P[{r},{c}]: ours {} theirs {expected}",
                cov[(r, c)]
            );
            worst = worst.max(d);
        }
    }
    println!("largest difference from PythonRobotics: {worst:e}");
}

/// Their final x_est: (x, y, yaw) then the landmarks in first-sight order (ids 1, 2, 3, 4, 0).
const REFERENCE_STATE: [f64; 13] = [
    -1.2373812218807347,
    4.000271395853989,
    -2.5536414241293484,
    14.92011157931544,
    10.239820759769449,
    2.8598839483542413,
    15.062662730772235,
    -5.144414128565181,
    19.972975577134086,
    7.985751659025067,
    8.101785684015546,
    10.078570323448496,
    -1.8696548502448642,
];

/// Their final P_est, row by row.
#[rustfmt::skip]
const REFERENCE_COVARIANCE: [[f64; 13]; 13] = [
    [0.26995025541555734, -0.020302787835916568, 0.010692977702727088, 0.14489849563169735, 0.05301799275964819, 0.09371581686686484, 0.00897970235260226, 0.053674494505196686, -0.047577994795189926, 0.15658576625622972, 0.024830955698987533, 0.1868159841617051, 0.013988918089200423],
    [-0.020302787835916634, 0.2728963885962798, -0.01526976505610393, 0.04085329830470223, 0.03597841615166502, 0.07829387275851404, 0.15333371494866235, 0.05041895827742702, 0.1986510217523024, 0.02603792027163546, 0.09460450046361069, -0.07541864151359501, 0.08408516763682365],
    [0.010692977702727084, -0.015269765056103928, 0.05481891311942584, -0.001515412355467985, 0.013172388983964101, -0.013871024938506865, -0.0039847548472246, -0.016931635244656087, -0.016967737335077254, -0.0007394995713023219, 0.006274202231624842, 0.01786650689408852, 0.008365198080339978],
    [0.14489849563169738, 0.04085329830470224, -0.001515412355467984, 0.23027524180023323, -0.12359514715272615, 0.14453354590182507, 0.03781661500952429, 0.10586292241342979, 0.027710555983308766, 0.16448714932270703, 0.002952286464728468, 0.10563090850044714, -0.0203241867102082],
    [0.05301799275964812, 0.03597841615166514, 0.0131723889839641, -0.12359514715272593, 0.43263259053531095, -0.09131674234876584, 0.08943967170904699, -0.09797139298703132, 0.003734952649209348, -0.012028582213483388, 0.17930426802743635, 0.1353372521708943, 0.18031661411494299],
    [0.09371581686686481, 0.07829387275851402, -0.01387102493850687, 0.1445335459018251, -0.09131674234876626, 0.4183177296098619, -0.006908115022235882, 0.16771171184816563, 0.07571663665638173, 0.13555804178954414, -0.040962923881698476, 0.024776764790770688, -0.05091692901901748],
    [0.008979702352602245, 0.1533337149486625, -0.0039847548472246065, 0.037816615009524275, 0.08943967170904712, -0.006908115022235718, 0.15748806589821926, -0.007234659828512151, 0.1473454567010159, 0.0262611359602113, 0.12270183837014081, -0.018219567407502493, 0.10878608721784151],
    [0.05367449450519675, 0.05041895827742702, -0.016931635244656087, 0.10586292241342969, -0.09797139298703121, 0.1677117118481657, -0.007234659828512127, 0.5765292271212938, 0.19927731167548055, 0.09877625797651131, -0.05715452846840737, -0.005369798380802068, -0.09265213143012954],
    [-0.047577994795189975, 0.19865102175230234, -0.016967737335077254, 0.027710555983308766, 0.003734952649209309, 0.07571663665638172, 0.1473454567010157, 0.1992773116754806, 0.2651852049080904, 0.008262981030780265, 0.07659388928092092, -0.11862152862903783, 0.05607776127060811],
    [0.15658576625622983, 0.026037920271635505, -0.0007394995713023134, 0.16448714932270705, -0.012028582213483022, 0.13555804178954411, 0.02626113596021134, 0.09877625797651123, 0.008262981030780275, 0.20091258028564296, -0.041274494025770346, 0.12297011689553917, -0.017540193329161367],
    [0.024830955698987186, 0.0946045004636106, 0.0062742022316248395, 0.00295228646472842, 0.17930426802743524, -0.040962923881698525, 0.12270183837014068, -0.05715452846840735, 0.07659388928092097, -0.04127449402577073, 0.22080580134519498, 0.06105318949498777, 0.151945651810346],
    [0.18681598416170525, -0.07541864151359498, 0.017866506894088516, 0.10563090850044707, 0.13533725217089493, 0.02477676479077082, -0.018219567407502486, -0.005369798380802018, -0.11862152862903781, 0.12297011689553926, 0.06105318949498781, 0.29331581399884976, 0.12226988380593364],
    [0.013988918089200499, 0.08408516763682367, 0.008365198080339965, -0.020324186710208313, 0.1803166141149436, -0.050916929019017246, 0.10878608721784147, -0.09265213143012933, 0.05607776127060812, -0.017540193329161104, 0.15194565181034558, 0.1222698838059337, 0.2953968384717329],
];
