//! Prints, as a Markdown table, how the PF's estimate approaches the KF's on a linear-Gaussian
//! problem as the particles grow (100, 1,000, 10,000): `cargo run --release -p
//! mole-localization --example pf_convergence`.

#[path = "../tests/common/pf_vs_kf.rs"]
mod pf_vs_kf;

fn main() {
    let rows: Vec<_> = [100, 1_000, 10_000]
        .iter()
        .map(|&j| pf_vs_kf::compare(j, 10, 200))
        .collect();
    print!("{}", pf_vs_kf::table(&rows));
}
