//! Generated files checked in beside the code that generates them (docs/messages.md, the Python
//! message classes, the step-rule table, the README's environment table, the architecture's
//! process table): a test compares the file's generated part with what the code says now.
//! `MOLE_BLESS=1` rewrites the part instead, for a developer who changed the code on purpose and
//! reviews the diff. Under CI (`CI` set) blessing is refused: a test that rewrites its own golden
//! passes whatever the code does.

use std::ffi::OsStr;
use std::ops::Range;
use std::path::Path;

/// The variable that makes golden tests rewrite their files.
pub const BLESS: &str = "MOLE_BLESS";

/// Whether golden tests should rewrite their files, from the values of `MOLE_BLESS` and `CI`;
/// an error when both are set.
pub fn blessing_from(bless: Option<&OsStr>, ci: Option<&OsStr>) -> Result<bool, String> {
    let set = |v: Option<&OsStr>| v.is_some_and(|v| !v.is_empty());
    match (set(bless), set(ci)) {
        (true, true) => Err(format!(
            "{BLESS} is set under CI: a golden file is never rewritten where it is checked"
        )),
        (bless, _) => Ok(bless),
    }
}

/// The whole text: for a file that is generated from start to end.
pub fn whole(text: &str) -> Option<Range<usize>> {
    Some(0..text.len())
}

/// Checks that the part of the file at `path` that `part` finds (`None`: the part's markers are
/// missing) is `expected`; with `MOLE_BLESS` set it writes `expected` there instead. Panics
/// with `regenerate` (the command that blesses) when they differ, or when blessing under CI.
pub fn check(
    path: &Path,
    expected: &str,
    part: impl Fn(&str) -> Option<Range<usize>>,
    regenerate: &str,
) {
    let bless = blessing_from(
        std::env::var_os(BLESS).as_deref(),
        std::env::var_os("CI").as_deref(),
    )
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let range = part(&text).unwrap_or_else(|| {
        panic!(
            "{}: the generated part's markers are missing",
            path.display()
        )
    });
    if bless {
        let blessed = format!("{}{expected}{}", &text[..range.start], &text[range.end..]);
        std::fs::write(path, blessed).unwrap_or_else(|e| panic!("write {}: {e}", path.display()));
        return;
    }
    assert!(
        text[range.clone()] == *expected,
        "{} differs from the code that generates it: regenerate it with `{BLESS}=1 {regenerate}` \
         and review the diff",
        path.display()
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Blessing needs `MOLE_BLESS`, and is refused with `CI` set; an empty value is unset.
    #[test]
    fn blessing_is_refused_under_ci() {
        let on = Some(OsStr::new("1"));
        let empty = Some(OsStr::new(""));
        assert_eq!(blessing_from(None, None), Ok(false));
        assert_eq!(blessing_from(on, None), Ok(true));
        assert_eq!(blessing_from(on, empty), Ok(true));
        assert_eq!(blessing_from(None, on), Ok(false));
        assert_eq!(blessing_from(empty, on), Ok(false));
        let refused = blessing_from(on, Some(OsStr::new("true"))).unwrap_err();
        assert!(refused.contains("MOLE_BLESS is set under CI"), "{refused}");
    }
}
