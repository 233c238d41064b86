//! Unknown correspondences: EKF-SLAM and FastSLAM associate readings by maximum likelihood
//! inside a χ² gate without looking at the ids; the test, which knows the true ids, scores them.
//! Through the libraries, and as the process runs them: readings whose id is
//! `LANDMARK_ANONYMOUS`, as the sensing process sends when the scenario hides the ids.

mod slam_sim;

use mole_localization::slam::{
    Association, Correspondence, EkfSlam, FastSlam, FastSlamConfig, SlamConfig, SlamError,
};
use mole_localization::{EkfSlamEstimator, Estimator, FastSlamEstimator, Readings};
use mole_types::{BeaconReading, Beacons, LANDMARK_ANONYMOUS, Odom, Pose2};
use nalgebra::Matrix3;
use slam_sim::{DT, landmarks, messages, simulate, world_map};
use std::collections::{BTreeMap, BTreeSet};

/// Steps per run: about one loop, so landmarks are met, left and met again.
const STEPS: usize = 300;
/// Seeded runs.
const SEEDS: u64 = 5;

fn unknown() -> SlamConfig {
    SlamConfig {
        correspondence: Correspondence::Unknown,
        ..SlamConfig::default()
    }
}

/// Association errors scored with the true ids.
#[derive(Debug, Default)]
struct Score {
    /// Readings matched or founding a landmark.
    decided: usize,
    /// Matched to a landmark founded by another beacon, or founding a duplicate of a mapped one.
    wrong: usize,
    /// Discarded between the gates.
    discarded: usize,
}

impl Score {
    /// Scores one decision: `mapped` holds the true ids already in the map.
    fn add(&mut self, reading: &BeaconReading, a: Association, mapped: &mut BTreeSet<u32>) {
        match a {
            Association::Matched { id, .. } => {
                self.decided += 1;
                self.wrong += usize::from(id != reading.id);
            }
            Association::New { id, .. } => {
                self.decided += 1;
                self.wrong += usize::from(!mapped.insert(id));
            }
            Association::Discarded => self.discarded += 1,
        }
    }

    fn rate(&self) -> f64 {
        self.wrong as f64 / self.decided as f64
    }
}

/// Error rate bound: the landmarks stand at least 3.4 m apart, the innovation covariance is
/// a few tenths of a metre (σ_r = 0.2 m, 5 m · σ_b = 0.25 m, plus the landmark and pose
/// uncertainty), so a wrong landmark sits some 10 σ away and the 99% gate should practically
/// never take it; the errors left are readings of a landmark founded a second time while its
/// first estimate was still poor, or a best particle that lost track. Measured over the five
/// seeds: EKF-SLAM 0 wrong of 7433 decisions, FastSLAM (100 particles) 2 of 7309 (0.03%); the
/// bound of 1% leaves room for other seeds and still fails for any systematic error (e.g. a
/// bearing sign error or an unwrapped bearing innovation).
const MAX_ERROR_RATE: f64 = 0.01;

/// EKF-SLAM with unknown correspondences: association error rate below the bound, every
/// beacon it saw mapped (new landmarks founded for unseen beacons), no duplicates.
#[test]
fn ekf_slam_associates_readings_without_ids() {
    let mut total = Score::default();
    for seed in 0..SEEDS {
        let mut slam = EkfSlam::new(
            Pose2::default(),
            Matrix3::zeros(),
            slam_sim::noise(),
            2 * landmarks().len(),
            unknown(),
        );
        let (mut mapped, mut seen) = (BTreeSet::new(), BTreeSet::new());
        for step in simulate(STEPS, seed) {
            slam.predict(step.v, step.omega, DT)
                .expect("plausible control");
            for r in &step.readings {
                seen.insert(r.id);
                if let Ok(a) = slam.correct_reading(r) {
                    total.add(r, a, &mut mapped);
                }
            }
        }
        let ids: Vec<u32> = slam.landmarks().map(|l| l.id).collect();
        assert_eq!(
            ids.iter().copied().collect::<BTreeSet<_>>(),
            seen,
            "seed {seed}"
        );
        assert_eq!(ids.len(), seen.len(), "seed {seed}: duplicates {ids:?}");
        let stats = slam.association_stats();
        assert_eq!(stats.created as usize, seen.len());
    }
    println!("EKF-SLAM: {total:?}, error rate {:.4}", total.rate());
    assert!(total.rate() < MAX_ERROR_RATE, "{total:?}");
}

/// FastSLAM with unknown correspondences (each particle associates on its own; the decisions
/// scored are the most likely particle's): error rate below the bound, every beacon mapped.
#[test]
fn fastslam_associates_readings_without_ids() {
    let mut total = Score::default();
    for seed in 0..SEEDS {
        let mut slam = FastSlam::new(
            Pose2::default(),
            slam_sim::noise(),
            2 * landmarks().len(),
            unknown(),
            FastSlamConfig {
                n_particles: 100,
                seed,
                ..FastSlamConfig::default()
            },
        );
        let (mut mapped, mut seen) = (BTreeSet::new(), BTreeSet::new());
        for step in simulate(STEPS, seed) {
            slam.predict(step.v, step.omega, DT)
                .expect("plausible control");
            for r in &step.readings {
                seen.insert(r.id);
                if let Ok(a) = slam.correct_reading(r) {
                    total.add(r, a, &mut mapped);
                }
            }
            slam.finish_correction();
        }
        let ids: BTreeSet<u32> = slam.landmarks().map(|l| l.id).collect();
        assert_eq!(ids, seen, "seed {seed}");
    }
    println!("FastSLAM: {total:?}, error rate {:.4}", total.rate());
    assert!(total.rate() < MAX_ERROR_RATE, "{total:?}");
}

/// Scores the decisions of a step without ids: `founders` maps each landmark slot to the true
/// id of the reading that founded it (a duplicate founding or a match to another beacon's
/// slot is an error).
fn score_anonymous(
    truth: &[BeaconReading],
    decisions: &[Result<Association, SlamError>],
    founders: &mut BTreeMap<usize, u32>,
    score: &mut Score,
) {
    for (reading, decision) in truth.iter().zip(decisions) {
        match decision {
            Ok(Association::Matched { slot, .. }) => {
                score.decided += 1;
                score.wrong += usize::from(founders.get(slot) != Some(&reading.id));
            }
            Ok(Association::New { slot, id }) => {
                assert_eq!(*id, LANDMARK_ANONYMOUS);
                score.decided += 1;
                score.wrong += usize::from(founders.values().any(|&t| t == reading.id));
                founders.insert(*slot, reading.id);
            }
            Ok(Association::Discarded) => score.discarded += 1,
            Err(_) => {}
        }
    }
}

/// The decision without the id, which anonymous readings cannot carry.
fn slot_decision(d: &Result<Association, SlamError>) -> Option<(bool, usize)> {
    match d {
        Ok(Association::Matched { slot, .. }) => Some((false, *slot)),
        Ok(Association::New { slot, .. }) => Some((true, *slot)),
        _ => None,
    }
}

/// EKF-SLAM as the process runs it, with anonymous readings: every reading carries
/// `LANDMARK_ANONYMOUS` and is associated by maximum likelihood or founds a landmark; scored
/// with the true ids the test keeps, the error rate stays below the bound; the landmarks are
/// published as anonymous.
#[test]
fn ekf_slam_estimator_associates_anonymous_readings() {
    let mut odom: Odom = bytemuck::Zeroable::zeroed();
    let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
    let mut score = Score::default();
    for seed in 0..SEEDS {
        let mut est = EkfSlamEstimator::from_map(&world_map(seed, &landmarks()));
        let mut founders = BTreeMap::new();
        for step in simulate(STEPS, seed) {
            messages(&step, Some(LANDMARK_ANONYMOUS), &mut odom, &mut beacons);
            est.step(&Readings::of(&odom).with_beacons(Some(&beacons)));
            score_anonymous(&step.readings, est.decisions(), &mut founders, &mut score);
        }
        let mut out = bytemuck::zeroed_box::<mole_types::Landmarks>();
        est.write_landmarks(&mut out);
        assert_eq!(out.n_landmarks as usize, founders.len(), "seed {seed}");
        assert!(out.landmarks().iter().all(|l| l.id == LANDMARK_ANONYMOUS));
    }
    println!(
        "EKF-SLAM estimator, anonymous readings: {score:?}, error rate {:.4}",
        score.rate()
    );
    assert!(
        score.decided > 0 && score.rate() < MAX_ERROR_RATE,
        "{score:?}"
    );
}

/// FastSLAM as the process runs it, with anonymous readings, decides exactly as the library
/// filter with unknown correspondences given the true ids as provenance (each particle keeps
/// its own slots, so a slot names a landmark only within one particle, and only the
/// provenance can score the most likely particle's decisions); scored that way the error rate
/// stays below the bound.
#[test]
fn fastslam_estimator_associates_anonymous_readings() {
    let mut odom: Odom = bytemuck::Zeroable::zeroed();
    let mut beacons: Box<Beacons> = bytemuck::zeroed_box();
    let mut score = Score::default();
    for seed in 0..SEEDS {
        let map = world_map(seed, &landmarks());
        let mut est = FastSlamEstimator::from_map(&map);
        let mut twin = FastSlam::new(
            Pose2::default(),
            slam_sim::noise(),
            mole_localization::slam::SLAM_CAPACITY,
            unknown(),
            FastSlamConfig {
                seed: map.seed,
                ..FastSlamConfig::default()
            },
        );
        let mut mapped = BTreeSet::new();
        for step in simulate(STEPS, seed) {
            messages(&step, Some(LANDMARK_ANONYMOUS), &mut odom, &mut beacons);
            est.step(&Readings::of(&odom).with_beacons(Some(&beacons)));
            twin.predict(step.v, step.omega, DT)
                .expect("plausible control");
            for (r, d) in step.readings.iter().zip(est.decisions()) {
                let t = twin.correct_reading(r);
                assert_eq!(slot_decision(d), slot_decision(&t), "seed {seed}");
                if let Ok(a) = t {
                    score.add(r, a, &mut mapped);
                }
            }
            twin.finish_correction();
        }
    }
    println!(
        "FastSLAM estimator, anonymous readings: {score:?}, error rate {:.4}",
        score.rate()
    );
    assert!(
        score.decided > 0 && score.rate() < MAX_ERROR_RATE,
        "{score:?}"
    );
}
