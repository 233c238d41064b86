//! A SLAM map's consistency over 100 seeded runs of EKF-SLAM on the ring, as the monitor judges
//! it: the mean landmark NEES of the published map (`localization/landmarks`) against the 95%
//! interval of the degrees of freedom the map carries (`nees_dof`, Satterthwaite's from the
//! joint covariance: the landmarks share the error of the poses they were seen from). Judged
//! as if the landmarks were independent (χ²₂ₙ/n), a consistent filter fails half its runs.

mod slam_sim;

use mole_localization::slam::Linearisation;
use mole_localization::{EkfSlamEstimator, Estimator, Readings};
use mole_monitor::{mean_nees_interval, mean_nees_interval_of_dof, nees_2d};
use mole_types::{Beacons, Landmarks, Odom};
use slam_sim::{landmarks, messages, simulate, world_map};

const RUNS: u64 = 100;

/// Runs inside the interval of the published ν and inside χ²₂ₙ/n, of `RUNS` runs of `steps`.
fn inside(steps: usize, linearisation: Linearisation) -> (u64, u64) {
    let truth = landmarks();
    let (mut by_dof, mut independent) = (0, 0);
    let mut odom: Odom = bytemuck::Zeroable::zeroed();
    let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
    let mut map: Box<Landmarks> = bytemuck::zeroed_box();
    for seed in 0..RUNS {
        let mut slam = EkfSlamEstimator::from_map(&world_map(seed, &truth));
        slam.filter_mut().linearisation = linearisation;
        for step in simulate(steps, seed).iter() {
            messages(step, None, &mut odom, &mut beacons);
            slam.step(&Readings::of(&odom).with_beacons(Some(&beacons)));
        }
        assert!(slam.write_landmarks(&mut map));
        let n = map.n_landmarks as usize;
        assert_eq!(n, truth.len(), "seed {seed}: every landmark mapped");
        let mean = map
            .landmarks()
            .iter()
            .map(|l| {
                let (x, y) = truth[l.id as usize];
                nees_2d(&[l.x - x, l.y - y], &l.covariance).expect("Σ positive definite")
            })
            .sum::<f64>()
            / n as f64;
        assert!(
            map.nees_dof >= 2.0 && map.nees_dof <= 2.0 * n as f64,
            "seed {seed}: ν {}",
            map.nees_dof
        );
        let [lo, hi] = mean_nees_interval_of_dof(map.nees_dof).expect("ν > 0");
        by_dof += u64::from((lo..=hi).contains(&mean));
        let [lo, hi] = mean_nees_interval(2, n as u32).expect("n > 0");
        independent += u64::from((lo..=hi).contains(&mean));
    }
    (by_dof, independent)
}

/// With its first-estimates Jacobians EKF-SLAM is consistent (slam_consistency.rs), and so are
/// its maps: over 1,000 steps (three laps) at least 90 of 100 runs' mean landmark NEES lies in
/// the interval of the ν they carry, while under χ²₂ₙ/n at most 70 do. Measured: 97 and 50
/// (ν about 2.8 of 18: the nine landmarks' errors are mostly one shared error).
#[test]
fn consistent_ekf_slam_maps_fall_in_their_nees_interval() {
    let (by_dof, independent) = inside(1000, Linearisation::FirstEstimates);
    println!("{by_dof} of {RUNS} inside by ν, {independent} by 2n");
    assert!(by_dof >= 90, "{by_dof} of {RUNS}");
    assert!(independent <= 70, "{independent} of {RUNS}");
}

/// Linearised at its estimates EKF-SLAM grows over-confident over ten laps (slam_consistency.rs),
/// and its maps fall outside the interval of their ν in many runs: fewer than 80 of 100 inside
/// over 3,000 steps. Measured: 66 (97 with the first estimates' Jacobians).
#[test]
fn over_confident_ekf_slam_maps_fall_outside_it() {
    let (by_dof, _) = inside(3000, Linearisation::Estimate);
    println!("{by_dof} of {RUNS} inside by ν");
    assert!(by_dof < 80, "{by_dof} of {RUNS}");
}
