//! The stored baselines (`eval/baselines/`, written by `scripts/eval-baselines.sh`): every suite
//! has its report, each report is of the suite it is filed as, and the README's planner and
//! estimator tables are the ones drawn from them.

use mole_launch::eval::baselines::{self, DIR};
use mole_types::golden;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Every suite's report is there, is of its family, planner and estimator, and ran every world
/// to its end; the README's blocks hold the tables drawn from them (`MOLE_BLESS=1` rewrites
/// them, as `scripts/eval-baselines.sh` does).
#[test]
fn every_suite_has_its_report_and_the_readme_tables_agree() {
    let reports = baselines::read_all(&root().join(DIR)).unwrap_or_else(|e| panic!("{e}"));
    for (suite, report) in &reports {
        let file = suite.file();
        assert_eq!(report.family, suite.family, "{file}");
        assert_eq!(report.planner, suite.planner.to_string(), "{file}");
        if let Some(estimator) = suite.estimator {
            assert_eq!(report.estimator, estimator.to_string(), "{file}");
        }
        assert!(!report.worlds.is_empty(), "{file}: no worlds");
        for w in &report.worlds {
            assert_eq!(w.exit_code, 0, "{file}: {} did not run to its end", w.world);
        }
    }
    let readme = root().join("README.md");
    for (name, table) in baselines::tables(&reports) {
        golden::check(
            &readme,
            &table,
            |text| baselines::block(text, name),
            "cargo test --test baselines",
        );
    }
}
