//! `mole replay --check`: a replay's outputs against the recording's, tick by tick, byte by
//! byte, naming the first field that differs.
//!
//! What may differ between two runs of the same lockstep inputs, and is not compared
//! ([`IGNORED`]): the header's `stamp_ns` and `origin_ns` (wall clock at publication and at the
//! truth it came from), its `seq` (a publisher's count, which a resent step moves without
//! changing any value), and the fields that measure wall-clock time: the pose's `update_ns`
//! (how long the estimator took) and the truth's `cmd_latency_ns` (the loop latency). Every
//! other byte, padding included, is the algorithms' output and must be the same.

use crate::tape::{Sample, TapeError, Window, for_each_sample};
use mole_types::layout::{self, TypeLayout};
use std::collections::BTreeMap;
use std::fmt;
use std::hash::{DefaultHasher, Hasher};
use std::path::Path;

/// Fields (struct, field) that carry wall-clock time, not the algorithms' output.
pub const IGNORED: &[(&str, &str)] = &[
    ("Header", "seq"),
    ("Header", "stamp_ns"),
    ("Header", "origin_ns"),
    ("Pose", "update_ns"),
    ("Truth", "cmd_latency_ns"),
];

/// The first difference between a recording and its replay.
#[derive(Debug, Clone, PartialEq)]
pub struct Difference {
    pub tick: u64,
    pub topic: String,
    pub what: What,
}

/// How a topic differs at a tick.
#[derive(Debug, Clone, PartialEq)]
pub enum What {
    /// Both have the sample; this field (`cells[1234]`, `header.tick`) differs first.
    Field {
        field: String,
        recorded: String,
        replayed: String,
    },
    /// The recording has the sample, the replay does not.
    Missing,
    /// The replay published a sample the recording does not have.
    Extra,
}

impl fmt::Display for Difference {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (tick, topic) = (self.tick, &self.topic);
        match &self.what {
            What::Field {
                field,
                recorded,
                replayed,
            } => write!(
                f,
                "tick {tick}: {topic} differs in field `{field}` (recorded {recorded}, replayed \
                 {replayed})"
            ),
            What::Missing => write!(
                f,
                "tick {tick}: {topic} was recorded but the replay did not publish it"
            ),
            What::Extra => write!(
                f,
                "tick {tick}: {topic} was published by the replay but is not in the recording"
            ),
        }
    }
}

/// What a comparison covered.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Compared {
    /// Samples found equal.
    pub samples: u64,
    /// The ticks compared.
    pub window: Window,
}

/// Compares `topics` of the `replayed` file with the `recorded` one over `window` (up to the
/// recording's last world tick), tick by tick in the order of `topics`. A topic the recording decimated
/// is compared at the ticks it kept. At the window's last tick a sample one side lacks is no
/// difference: the run ended there and its roles were stopped as they finished it.
pub fn compare(
    recorded: &Path,
    replayed: &Path,
    topics: &[&str],
    window: Window,
) -> Result<Result<Compared, Difference>, TapeError> {
    let facts = crate::tape::read_tape(recorded, &[], Window::ALL)?;
    let window = Window {
        from: window.from,
        to: window
            .to
            .min(facts.ticks().map_or(u64::MAX, |(_, last)| last)),
    };
    let ours = digests(recorded, topics)?;
    let theirs = digests(replayed, topics)?;
    let mut keys: Vec<(u64, usize)> = ours.keys().chain(theirs.keys()).copied().collect();
    keys.sort_unstable();
    keys.dedup();
    let mut samples = 0;
    for (tick, index) in keys.into_iter().filter(|(t, _)| window.contains(*t)) {
        let topic = topics[index];
        let difference = |what| Difference {
            tick,
            topic: topic.to_string(),
            what,
        };
        match (ours.get(&(tick, index)), theirs.get(&(tick, index))) {
            (Some(a), Some(b)) if a == b => samples += 1,
            (Some(_), Some(_)) => {
                let a = sample_at(recorded, topic, tick)?;
                let b = sample_at(replayed, topic, tick)?;
                return Ok(Err(difference(first_field(&a, &b))));
            }
            _ if tick == window.to => {}
            (Some(_), None) => return Ok(Err(difference(What::Missing))),
            (None, _) if facts.recording.contains_key(&format!("decimated.{topic}")) => {}
            (None, _) => return Ok(Err(difference(What::Extra))),
        }
    }
    Ok(Ok(Compared { samples, window }))
}

/// A digest of every sample of `topics`, by (tick, topic index), its ignored fields left out.
fn digests(path: &Path, topics: &[&str]) -> Result<BTreeMap<(u64, usize), u64>, TapeError> {
    let types = layout::all();
    let mut out = BTreeMap::new();
    for_each_sample(path, topics, |sample| {
        let index = topics.iter().position(|t| *t == sample.topic);
        if let Some(index) = index {
            let data = masked(&types, &sample);
            let mut hasher = DefaultHasher::new();
            hasher.write(&data);
            out.entry((sample.tick, index)).or_insert(hasher.finish());
        }
    })?;
    Ok(out)
}

/// The first sample of `topic` at `tick` in `path`.
fn sample_at(path: &Path, topic: &str, tick: u64) -> Result<Sample, TapeError> {
    let mut found = None;
    for_each_sample(path, &[topic], |sample| {
        if sample.tick == tick && found.is_none() {
            found = Some(sample);
        }
    })?;
    found.ok_or_else(|| TapeError::Corrupt(path.to_path_buf(), format!("{topic} changed")))
}

/// The message type of a topic.
fn type_of<'a>(types: &'a [TypeLayout], topic: &str) -> Option<&'a TypeLayout> {
    let (_, type_name) = mole_types::topics::all()
        .into_iter()
        .find(|(t, _)| *t == topic)?;
    types.iter().find(|t| t.type_name == type_name)
}

/// The sample's bytes with its ignored fields zeroed.
fn masked(types: &[TypeLayout], sample: &Sample) -> Vec<u8> {
    let mut data = sample.data.clone();
    if let Some(t) = type_of(types, &sample.topic) {
        for (start, end) in ignored_ranges(types, t, 0) {
            data[start..end].fill(0);
        }
    }
    data
}

/// The byte ranges of the [`IGNORED`] fields of `t` (placed at `base`) and of the structs it
/// holds directly.
fn ignored_ranges(types: &[TypeLayout], t: &TypeLayout, base: usize) -> Vec<(usize, usize)> {
    let mut ranges = Vec::new();
    for field in &t.fields {
        let start = base + field.offset;
        if IGNORED.contains(&(t.rust_name, field.name)) {
            ranges.push((start, start + field.size));
        } else if let Some(inner) = types.iter().find(|s| s.rust_name == field.ty) {
            ranges.extend(ignored_ranges(types, inner, start));
        }
    }
    ranges
}

/// The first field, outside the ignored ones, in which two samples of a topic differ.
fn first_field(recorded: &Sample, replayed: &Sample) -> What {
    let types = layout::all();
    let (a, b) = (masked(&types, recorded), masked(&types, replayed));
    let Some(at) = a.iter().zip(&b).position(|(x, y)| x != y) else {
        return What::Field {
            field: "(size)".into(),
            recorded: format!("{} bytes", a.len()),
            replayed: format!("{} bytes", b.len()),
        };
    };
    let (field, primitive, start) = match type_of(&types, &recorded.topic) {
        Some(t) => locate(&types, t.rust_name, at),
        None => (format!("byte {at}"), "u8".to_string(), at),
    };
    let value = |data: &[u8]| decode(&primitive, &data[start..]);
    What::Field {
        field,
        recorded: value(&a),
        replayed: value(&b),
    }
}

/// The size of a type named as the layout table names it (`f64`, `Grid`, `[[f32; 2]; 64]`).
fn size_of(types: &[TypeLayout], ty: &str) -> usize {
    if let Some((element, n)) = array(ty) {
        return size_of(types, element) * n;
    }
    primitive_size(ty).unwrap_or_else(|| {
        types
            .iter()
            .find(|t| t.rust_name == ty)
            .map_or(1, |t| t.size)
    })
}

fn primitive_size(ty: &str) -> Option<usize> {
    Some(match ty {
        "u8" | "i8" => 1,
        "u16" | "i16" => 2,
        "u32" | "i32" | "f32" => 4,
        "u64" | "i64" | "f64" => 8,
        _ => return None,
    })
}

/// `[T; N]` → (`T`, N).
fn array(ty: &str) -> Option<(&str, usize)> {
    let inner = ty.strip_prefix('[')?.strip_suffix(']')?;
    let (element, n) = inner.rsplit_once("; ")?;
    Some((element, n.parse().ok()?))
}

/// The field path of byte `at` of a `ty` (`landmarks[2].x`), the primitive there and where that
/// primitive starts.
fn locate(types: &[TypeLayout], ty: &str, at: usize) -> (String, String, usize) {
    if let Some((element, _)) = array(ty) {
        let size = size_of(types, element).max(1);
        let (index, rest) = (at / size, at % size);
        let (path, primitive, start) = locate(types, element, rest);
        return (format!("[{index}]{path}"), primitive, index * size + start);
    }
    let Some(t) = types.iter().find(|t| t.rust_name == ty) else {
        return (String::new(), ty.to_string(), 0);
    };
    let Some(field) = t
        .fields
        .iter()
        .find(|f| (f.offset..f.offset + f.size).contains(&at))
    else {
        return (format!(".byte {at}"), "u8".to_string(), at);
    };
    let (path, primitive, start) = locate(types, &field.ty, at - field.offset);
    let dot = if path.starts_with('[') || path.is_empty() {
        ""
    } else {
        "."
    };
    let name = format!("{}{dot}{path}", field.name);
    (name, primitive, field.offset + start)
}

/// A primitive's value, little-endian, at the start of `bytes`.
fn decode(primitive: &str, bytes: &[u8]) -> String {
    let n = primitive_size(primitive).unwrap_or(1).min(bytes.len());
    let mut word = [0u8; 8];
    word[..n].copy_from_slice(&bytes[..n]);
    let word = u64::from_le_bytes(word);
    match primitive {
        "f64" => f64::from_bits(word).to_string(),
        "f32" => f32::from_bits(word as u32).to_string(),
        "i8" => (word as i8).to_string(),
        "i16" => (word as i16).to_string(),
        "i32" => (word as i32).to_string(),
        "i64" => (word as i64).to_string(),
        _ => word.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tape::tests::{TempFile, sample, truth, write};
    use mole_types::{Grid, Pose, topics};

    fn pose(tick: u64, x: f64, update_ns: u64) -> Pose {
        let mut p: Pose = bytemuck::Zeroable::zeroed();
        (p.header.tick, p.x, p.update_ns) = (tick, x, update_ns);
        p.header.stamp_ns = tick * 1000 + update_ns;
        p
    }

    fn grid(tick: u64, cell: usize) -> Grid {
        let mut g: Grid = bytemuck::Zeroable::zeroed();
        g.header.tick = tick;
        g.cells[cell] = 1;
        g
    }

    const COMPARED: &[&str] = &[topics::LOCALIZATION_POSE.name, topics::MAPPING_GRID.name];

    /// Files written from `poses` and `grids` (tick, value) for the comparison.
    fn files(name: &str, poses: &[(u64, f64, u64)], grids: &[(u64, usize)]) -> TempFile {
        let file = TempFile::new(name);
        let mut records = vec![sample(topics::WORLD_TRUTH.name, &truth(0, 0.0))];
        records.extend(
            poses
                .iter()
                .map(|&(k, x, ns)| sample(topics::LOCALIZATION_POSE.name, &pose(k, x, ns))),
        );
        records.extend(
            grids
                .iter()
                .map(|&(k, cell)| sample(topics::MAPPING_GRID.name, &grid(k, cell))),
        );
        write(&file.0, records);
        file
    }

    /// The same outputs with other wall-clock stamps and estimator timings are equal.
    #[test]
    fn wall_clock_fields_are_not_compared() {
        let a = files("same-a", &[(0, 1.0, 5), (1, 2.0, 6)], &[(0, 3), (1, 4)]);
        let b = files("same-b", &[(0, 1.0, 900), (1, 2.0, 17)], &[(0, 3), (1, 4)]);
        let compared = compare(&a.0, &b.0, COMPARED, Window::ALL)
            .unwrap()
            .expect("equal");
        assert_eq!(compared.samples, 4);
    }

    /// The first differing field is named with its tick, its topic and both values; an array
    /// element by its index.
    #[test]
    fn the_first_difference_names_tick_topic_and_field() {
        let a = files(
            "diff-a",
            &[(0, 1.0, 5), (1, 2.0, 5), (2, 3.0, 5)],
            &[(0, 3), (1, 4)],
        );
        let b = files(
            "diff-b",
            &[(0, 1.0, 5), (1, 2.5, 5), (2, 3.5, 5)],
            &[(0, 3), (1, 9)],
        );
        let d = compare(&a.0, &b.0, COMPARED, Window::ALL)
            .unwrap()
            .expect_err("differs");
        assert_eq!(
            d.to_string(),
            "tick 1: localization/pose differs in field `x` (recorded 2, replayed 2.5)"
        );
        let b = files(
            "cell-b",
            &[(0, 1.0, 5), (1, 2.0, 5), (2, 3.0, 5)],
            &[(0, 3), (1, 9)],
        );
        let d = compare(&a.0, &b.0, COMPARED, Window::ALL)
            .unwrap()
            .expect_err("differs");
        assert_eq!(d.tick, 1);
        assert_eq!(d.topic, topics::MAPPING_GRID.name);
        assert!(
            d.to_string()
                .contains("field `cells[4]` (recorded 1, replayed 0)"),
            "{d}"
        );
    }

    /// A sample the replay lacks is a difference, but at the last tick, where the run ended.
    #[test]
    fn a_missing_sample_is_a_difference_but_at_the_end() {
        let a = files("miss-a", &[(0, 1.0, 5), (1, 2.0, 5), (2, 3.0, 5)], &[]);
        let b = files("miss-b", &[(0, 1.0, 5), (2, 3.0, 5)], &[]);
        let d = compare(&a.0, &b.0, COMPARED, Window::ALL)
            .unwrap()
            .expect_err("missing");
        assert_eq!((d.tick, d.what), (1, What::Missing));
        let b = files("end-b", &[(0, 1.0, 5), (1, 2.0, 5)], &[]);
        assert!(compare(&a.0, &b.0, COMPARED, Window::ALL).unwrap().is_ok());
    }
}
