//! On a linear-Gaussian problem the PF's mean converges to the KF's (the exact posterior) as the
//! particles grow, and its RMSE falls towards the KF's. `cargo run --example pf_convergence`
//! prints the same table with more seeds.

mod common {
    pub mod pf_vs_kf;
}
use common::pf_vs_kf::{compare, table};

#[test]
fn pf_mean_converges_to_the_kf_mean_as_particles_grow() {
    let rows: Vec<_> = [100, 1_000, 10_000]
        .iter()
        .map(|&j| compare(j, 3, 100))
        .collect();
    eprintln!("{}", table(&rows));
    // Monte-Carlo error ∝ 1/√J: ×10 particles should cut the distance to the KF by ~3.2; ask 1.8.
    for w in rows.windows(2) {
        assert!(
            w[1].rms_to_kf * 1.8 < w[0].rms_to_kf,
            "J = {} → {}: {} → {}",
            w[0].particles,
            w[1].particles,
            w[0].rms_to_kf,
            w[1].rms_to_kf
        );
    }
    // RMSE falls monotonically towards the KF's (the same data for every J), never below it by
    // more than noise.
    assert!(rows[0].rmse > rows[1].rmse && rows[1].rmse > rows[2].rmse);
    assert!(rows[0].rmse > rows[2].rmse * 1.01);
    assert!(rows[2].rmse < rows[2].kf_rmse * 1.02);
    assert!(rows[2].rmse > rows[2].kf_rmse * 0.98);
}
