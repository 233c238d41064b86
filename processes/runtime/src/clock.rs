//! The two clock modes (declared in `mole_types::kinds`) and the parsing of points from the
//! command line. When a process handles a step is decided by the step loop (`step.rs`).

pub use mole_types::ClockMode;

/// Parses `X,Y` (metres) from a command line or an environment variable, e.g. `--goal 8.5,9`.
pub fn parse_point(text: &str) -> Result<(f64, f64), String> {
    let parsed = text.split_once(',').and_then(|(x, y)| {
        let (x, y) = (x.trim().parse::<f64>().ok()?, y.trim().parse::<f64>().ok()?);
        (x.is_finite() && y.is_finite()).then_some((x, y))
    });
    parsed.ok_or_else(|| format!("expected X,Y in metres (e.g. 8.5,9), found `{text}`"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_parse_and_bad_ones_are_named() {
        assert_eq!(parse_point("8.5, 9"), Ok((8.5, 9.0)));
        assert!(parse_point("8.5").unwrap_err().contains("`8.5`"));
        assert!(parse_point("nan,1").is_err());
    }
}
