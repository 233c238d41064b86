//! The layout table: every message type's name, size, alignment and field offsets.
//!
//! `docs/messages.md` is generated from [`markdown`] and a test checks that it matches, so the
//! document other languages code against cannot drift from the Rust types. Each type's entry,
//! its size assertion and its no-padding assertion are derived (`#[derive(Message)]`,
//! `#[derive(Layout)]`, crate mole-types-derive); `bytemuck::Pod` refuses implicit padding too.

use crate::control::*;
use crate::messages::*;
use core::mem::{align_of, offset_of, size_of};

/// One field of a message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldLayout {
    pub name: &'static str,
    pub offset: usize,
    pub size: usize,
    /// The Rust type, without its module path, e.g. `f64`, `[f32; 1024]`, `Header`.
    pub ty: String,
}

/// One message type.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TypeLayout {
    pub rust_name: &'static str,
    pub type_name: &'static str,
    pub size: usize,
    pub align: usize,
    pub fields: Vec<FieldLayout>,
}

fn short_type_name(full: &str) -> String {
    // "[mole_types::geometry::Square; 2048]" -> "[Square; 2048]"
    let mut out = String::new();
    let mut word = String::new();
    for c in full.chars() {
        if c.is_alphanumeric() || c == '_' || c == ':' {
            word.push(c);
        } else {
            out.push_str(word.rsplit("::").next().unwrap_or(&word));
            word.clear();
            out.push(c);
        }
    }
    out.push_str(word.rsplit("::").next().unwrap_or(&word));
    out
}

impl FieldLayout {
    /// A field of type `F` named `name` at `offset` (what `#[derive(Layout)]` lists).
    pub fn of<F>(name: &'static str, offset: usize) -> FieldLayout {
        FieldLayout {
            name,
            offset,
            size: size_of::<F>(),
            ty: short_type_name(core::any::type_name::<F>()),
        }
    }
}

impl TypeLayout {
    /// The layout of `T`, named `rust_name`, with `fields` (what `#[derive(Layout)]` writes).
    pub fn of<T: iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend>(
        rust_name: &'static str,
        fields: Vec<FieldLayout>,
    ) -> TypeLayout {
        TypeLayout {
            rust_name,
            // SAFETY: `type_name` only returns the `#[type_name]` literal of the derive.
            type_name: unsafe {
                <T as iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend>::type_name()
            },
            size: size_of::<T>(),
            align: align_of::<T>(),
            fields,
        }
    }
}

/// A type that crosses a process boundary, with its entry in the layout table: derived by
/// `#[derive(Message)]` and `#[derive(Layout)]`, never written by hand.
pub trait Layout {
    /// Its name, size, alignment and fields.
    fn layout() -> TypeLayout;
    /// Hands `visit` the layout of every struct its fields embed, depth first.
    fn visit_embedded(visit: &mut dyn FnMut(TypeLayout));
}

/// What a field's type adds to the layout table: an embedded struct its own entry (and those it
/// embeds), an array its element's, a number nothing.
pub trait FieldType {
    /// Hands `visit` the layouts this field type brings.
    fn visit(_visit: &mut dyn FnMut(TypeLayout)) {}
}

macro_rules! numbers {
    ($($t:ty),+) => { $(impl FieldType for $t {})+ };
}
numbers!(u8, u16, u32, u64, i8, i16, i32, i64, f32, f64);

impl<T: FieldType, const N: usize> FieldType for [T; N] {
    fn visit(visit: &mut dyn FnMut(TypeLayout)) {
        T::visit(visit);
    }
}

/// Every type that crosses a process boundary: the message of each topic in the topic table's
/// order, then the control service's request and response, then the structs they embed.
pub fn all() -> Vec<TypeLayout> {
    struct Collect(Vec<TypeLayout>);
    impl crate::topics::TopicVisitor for Collect {
        fn visit<M: crate::Message>(&mut self, _constant: &'static str, _: crate::Topic<M>) {
            self.0.push(M::layout());
        }
    }
    let mut messages = Collect(Vec::new());
    crate::topics::for_each(&mut messages);
    messages.0.push(ControlRequest::layout());
    messages.0.push(ControlResponse::layout());
    let mut embedded = Vec::new();
    let mut collect = |t: TypeLayout| embedded.push(t);
    crate::topics::for_each(&mut Embedded(&mut collect));
    ControlRequest::visit_embedded(&mut collect);
    ControlResponse::visit_embedded(&mut collect);
    let mut out: Vec<TypeLayout> = Vec::new();
    for t in messages.0.into_iter().chain(embedded) {
        if !out.iter().any(|o| o.rust_name == t.rust_name) {
            out.push(t);
        }
    }
    out
}

/// Hands every embedded struct of each topic's message to a closure.
struct Embedded<'a>(&'a mut dyn FnMut(TypeLayout));

impl crate::topics::TopicVisitor for Embedded<'_> {
    fn visit<M: crate::Message>(&mut self, _constant: &'static str, _: crate::Topic<M>) {
        M::visit_embedded(self.0);
    }
}

/// The layout table as Markdown: the text of `docs/messages.md`.
pub fn markdown() -> String {
    use core::fmt::Write;
    let mut s = String::new();
    s.push_str("# Message layouts\n\n");
    s.push_str(
        "Generated from `shared-types/src/layout.rs` (regenerate with `MOLE_BLESS=1 cargo test -p \
         mole-types`); a test fails when this file and the code differ.\n\n",
    );
    s.push_str(
        "Every type is `#[repr(C)]`, little-endian on every supported target, with explicit \
         `_pad` fields and no implicit padding. A process in another language must use exactly \
         these type names, sizes and offsets. Topics and their types:\n\n",
    );
    s.push_str("| topic | type_name |\n| --- | --- |\n");
    for (topic, ty) in crate::topics::all() {
        let _ = writeln!(s, "| {topic} | `{ty}` |");
    }
    for t in all() {
        let _ = writeln!(
            s,
            "\n## {} (`{}`)\n\nsize {} bytes, alignment {}\n\n| field | offset | size | type |\n| --- | ---: | ---: | --- |",
            t.rust_name, t.type_name, t.size, t.align
        );
        for f in &t.fields {
            let _ = writeln!(s, "| {} | {} | {} | `{}` |", f.name, f.offset, f.size, f.ty);
        }
    }
    s
}

/// A constant of `messages.rs` that other languages need (capacities, flags, mode codes).
macro_rules! constants {
    ($($c:ident),+ $(,)?) => {
        vec![$((stringify!($c).to_owned(), $c as u64)),+]
    };
}

/// The wire codes of a choice (`crate::kinds`), named `PREFIX_NAME` (`ESTIMATOR_EKF_SLAM`).
fn choice_codes(prefix: &str, names: &[&str], code: impl Fn(usize) -> u32) -> Vec<(String, u64)> {
    names
        .iter()
        .enumerate()
        .map(|(i, name)| {
            let name = name.replace('-', "_").to_ascii_uppercase();
            (format!("{prefix}_{name}"), u64::from(code(i)))
        })
        .collect()
}

/// Every `pub const` of `messages.rs`, by name (a test checks that none is missing), then the
/// wire codes of the choices in `kinds.rs`.
fn constants() -> Vec<(String, u64)> {
    use crate::{ClockMode, EndReason, EstimatorKind};
    let mut all = constants![
        MAX_OBSTACLES,
        MAX_BEACONS,
        MAX_BEAMS,
        MAX_TACTILE,
        MAX_CONTACTS,
        MAX_GRID_CELLS,
        MAX_PARTICLES,
        MAX_LANDMARKS,
        MAX_TRAJECTORY_POSES,
        MAX_PATH,
        MAX_TOPIC_STATS,
        NAME_LEN,
        MAX_PROCESSES,
        TRUTH_END,
        TRUTH_GOAL_REACHED,
        TRUTH_IN_CONTACT,
        END_NONE,
        LANDMARK_ANONYMOUS,
        GRID_FRONTIER,
        GRID_CONTACT,
        CELL_UNEXPLORED,
        CELL_FREE,
        CELL_OCCUPIED,
        MODE_IDLE,
        MODE_EXPLORE,
        MODE_BOUNCE_BACK,
        MODE_GOAL,
        MODE_STALLED,
        MODE_ESCAPE,
        MODE_DONE,
        MODE_ARRIVED,
        STATUS_HAS_GOAL,
        STATUS_HAS_FRONTIER,
        STATUS_EXPLORATION_COMPLETE,
        TICK_END,
        DIRECTION_SUBSCRIBE,
        DIRECTION_PUBLISH,
        PROCESS_STARTING,
        PROCESS_RUNNING,
        PROCESS_RESTARTING,
        PROCESS_EXITED,
        PROCESS_FAILED,
        PACE_RUN,
        PACE_PAUSE,
        PACE_STEP,
        PACE_MAX_STEPS,
    ];
    all.extend(choice_codes("END", EndReason::NAMES, |i| {
        EndReason::ALL[i].code()
    }));
    all.extend(choice_codes("ESTIMATOR", EstimatorKind::NAMES, |i| {
        EstimatorKind::ALL[i].code()
    }));
    all.extend(choice_codes("CLOCK", ClockMode::NAMES, |i| {
        ClockMode::ALL[i].code()
    }));
    all.extend(choice_codes("FAULT", crate::FaultKind::NAMES, |i| {
        crate::FaultKind::ALL[i].code()
    }));
    all
}

/// One topic with what its service must hold, for other languages to open it compatibly.
#[derive(Debug, Clone, PartialEq, Eq)]
struct TopicLayout {
    /// The constant's name in `topics.rs`, e.g. `SENSING_SCAN`.
    constant: &'static str,
    /// The name below the namespace, e.g. `sensing/scan`.
    name: &'static str,
    type_name: &'static str,
    history: usize,
    buffer: usize,
    max_publishers: usize,
    max_subscribers: usize,
}

fn topic_layout<M: crate::Message>(constant: &'static str, t: crate::Topic<M>) -> TopicLayout {
    TopicLayout {
        constant,
        name: t.name,
        type_name: M::wire_type_name(),
        history: t.history,
        buffer: t.buffer,
        max_publishers: t.max_publishers,
        max_subscribers: t.max_subscribers,
    }
}

/// Every topic of `topics::all`, in its order, with its service settings.
fn topics() -> Vec<TopicLayout> {
    struct Collect(Vec<TopicLayout>);
    impl crate::topics::TopicVisitor for Collect {
        fn visit<M: crate::Message>(&mut self, constant: &'static str, topic: crate::Topic<M>) {
            self.0.push(topic_layout(constant, topic));
        }
    }
    let mut collect = Collect(Vec::new());
    crate::topics::for_each(&mut collect);
    collect.0
}

/// The ctypes expression of a field's Rust type (`[f32; 2]` → `ctypes.c_float * 2`).
///
/// # Panics
/// On a type no message may hold (the message rules allow only integers, floats, arrays and the
/// message structs): the layout table itself is then wrong.
fn ctype(ty: &str, structs: &[&str]) -> String {
    if let Some((element, n)) = ty
        .strip_prefix('[')
        .and_then(|s| s.strip_suffix(']'))
        .and_then(|s| s.rsplit_once("; "))
    {
        let element = ctype(element, structs);
        return if element.contains(" * ") {
            format!("({element}) * {n}")
        } else {
            format!("{element} * {n}")
        };
    }
    let primitive = match ty {
        "u8" => "c_uint8",
        "u16" => "c_uint16",
        "u32" => "c_uint32",
        "u64" => "c_uint64",
        "i8" => "c_int8",
        "i16" => "c_int16",
        "i32" => "c_int32",
        "i64" => "c_int64",
        "f32" => "c_float",
        "f64" => "c_double",
        other if structs.contains(&other) => return other.to_string(),
        other => panic!("no ctypes equivalent for the field type `{other}`"),
    };
    format!("ctypes.{primitive}")
}

/// Writes `items` joined by ", " as lines of at most 99 characters, each starting with `indent`.
fn wrapped(items: &[String], indent: &str) -> String {
    let mut out = String::new();
    let mut line = String::from(indent);
    for item in items {
        if line.len() > indent.len() && line.len() + item.len() + 2 > 99 {
            out.push_str(line.trim_end());
            out.push('\n');
            line = String::from(indent);
        }
        line.push_str(item);
        line.push_str(", ");
    }
    out.push_str(line.trim_end());
    out.push('\n');
    out
}

/// Indices of `types` with every struct before the types whose fields name it.
fn dependency_order(types: &[TypeLayout]) -> Vec<usize> {
    fn visit(i: usize, types: &[TypeLayout], order: &mut Vec<usize>) {
        if order.contains(&i) {
            return;
        }
        for f in &types[i].fields {
            for word in f.ty.split(|c: char| !(c.is_alphanumeric() || c == '_')) {
                if let Some(j) = types.iter().position(|t| t.rust_name == word)
                    && j != i
                {
                    visit(j, types, order);
                }
            }
        }
        order.push(i);
    }
    let mut order = Vec::with_capacity(types.len());
    for i in 0..types.len() {
        visit(i, types, &mut order);
    }
    order
}

/// The layout table as a Python module of `ctypes.Structure` classes, constants and topics: the
/// text of `examples/python_planner/mole_messages.py`.
///
/// Each class has a `type_name()` classmethod: the iceoryx2 Python binding records that name,
/// `ctypes.sizeof` and `ctypes.alignment` as the service's payload type, and opening a service
/// fails unless all three equal the Rust side's. Structs are emitted before the messages that
/// embed them; importing the module checks every size, alignment and field offset.
///
/// # Panics
/// When the layout table is wrong: a field type without a ctypes equivalent, or a topic whose
/// message [`all`] does not list.
pub fn python_ctypes() -> String {
    use core::fmt::Write;
    let types = all();
    let structs: Vec<&str> = types.iter().map(|t| t.rust_name).collect();
    let mut s = String::new();
    s.push_str(
        r#""""mole's messages as ctypes structures, for processes written in Python.

Generated from shared-types/src/layout.rs: do not edit. Regenerate it with
`MOLE_BLESS=1 cargo test -p mole-types`; a test fails when this file and the Rust types differ.

Each class's type_name() is what the iceoryx2 Python package records as the service's payload
type, with ctypes.sizeof() and ctypes.alignment(): all three must equal the Rust side's, or
opening the service fails with incompatible types. Importing this module checks every size,
alignment and field offset against the Rust types.
"""

import ctypes
from typing import NamedTuple


def _check(cls, size, alignment, offsets):
    """Refuses to load when ctypes lays a class out otherwise than Rust does."""
    fields = [getattr(cls, name).offset for name, _ in cls._fields_]
    actual = (ctypes.sizeof(cls), ctypes.alignment(cls), fields)
    if actual != (size, alignment, offsets):
        raise TypeError(f"{cls.__name__}: ctypes {actual}, Rust {(size, alignment, offsets)}")
"#,
    );
    for i in dependency_order(&types) {
        let t = &types[i];
        let _ = write!(
            s,
            "\n\nclass {}(ctypes.Structure):\n    \"\"\"`{}`: {} bytes, alignment {}.\"\"\"\n\n    _fields_ = [\n",
            t.rust_name, t.type_name, t.size, t.align
        );
        for f in &t.fields {
            let _ = writeln!(s, "        (\"{}\", {}),", f.name, ctype(&f.ty, &structs));
        }
        let _ = write!(
            s,
            "    ]\n\n    @classmethod\n    def type_name(cls) -> str:\n        return \"{}\"\n\n\n",
            t.type_name
        );
        let offsets: Vec<String> = t.fields.iter().map(|f| f.offset.to_string()).collect();
        let head = format!("_check({}, {}, {}, [", t.rust_name, t.size, t.align);
        let one_line = format!("{head}{}])", offsets.join(", "));
        if one_line.len() <= 99 {
            s.push_str(&one_line);
            s.push('\n');
        } else {
            s.push_str(&head);
            s.push('\n');
            s.push_str(&wrapped(&offsets, "    "));
            s.push_str("])\n");
        }
    }
    s.push_str("\n\n# The constants of shared-types/src/messages.rs.\n");
    for (name, value) in constants() {
        let _ = writeln!(s, "{name} = {value}");
    }
    s.push_str(
        r#"

class Topic(NamedTuple):
    """A topic: its name below the namespace, its message, and what its service holds."""

    name: str
    message: type
    history: int
    buffer: int
    max_publishers: int
    max_subscribers: int

"#,
    );
    for t in topics() {
        let class = types
            .iter()
            .find(|l| l.type_name == t.type_name)
            .map(|l| l.rust_name)
            .unwrap_or_else(|| panic!("{} carries {}, which all() lacks", t.name, t.type_name));
        let _ = writeln!(
            s,
            "\n{} = Topic(\n    \"{}\", {class}, history={}, buffer={}, max_publishers={}, max_subscribers={}\n)",
            t.constant, t.name, t.history, t.buffer, t.max_publishers, t.max_subscribers
        );
    }
    let constants: Vec<String> = topics().iter().map(|t| t.constant.to_string()).collect();
    s.push_str("\nTOPICS = (\n");
    s.push_str(&wrapped(&constants, "    "));
    s.push_str(")\n");
    let template = crate::topics::service_name("{namespace}", "{topic}");
    let _ = write!(
        s,
        "\n\ndef service_name(namespace: str, topic: str) -> str:\n    \"\"\"The iceoryx2 service name of a topic in a namespace.\"\"\"\n    return f\"{template}\"\n"
    );
    s
}

// Offsets other languages rely on; the sizes are asserted where each type is declared
// (`#[layout(size = …)]`).
const _: () = {
    assert!(offset_of!(WorldMap, header) == 0);
    assert!(offset_of!(Grid, cells) == 72);
    assert!(offset_of!(Scan, ranges) == 48);
};

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_field_is_listed_and_fields_tile_the_type() {
        for t in all() {
            let mut end = 0;
            for f in &t.fields {
                assert_eq!(f.offset, end, "{}.{} leaves a gap", t.rust_name, f.name);
                end = f.offset + f.size;
            }
            assert_eq!(end, t.size, "{} has unlisted fields", t.rust_name);
            assert!(t.type_name.starts_with("mole.") && t.type_name.contains(".v"));
        }
    }

    #[test]
    fn short_type_names_drop_module_paths() {
        assert_eq!(
            short_type_name("[mole_types::geometry::Square; 2048]"),
            "[Square; 2048]"
        );
        assert_eq!(short_type_name("f64"), "f64");
        assert_eq!(short_type_name("[[f32; 2]; 512]"), "[[f32; 2]; 512]");
    }

    #[test]
    fn docs_messages_md_matches_the_code() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/messages.md");
        crate::golden::check(
            path.as_ref(),
            &markdown(),
            crate::golden::whole,
            "cargo test -p mole-types",
        );
    }
    #[test]
    fn python_planner_mole_messages_py_matches_the_code() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../examples/python_planner/mole_messages.py"
        );
        crate::golden::check(
            path.as_ref(),
            &python_ctypes(),
            crate::golden::whole,
            "cargo test -p mole-types",
        );
    }

    #[test]
    fn ctypes_of_field_types() {
        let structs = ["Square"];
        assert_eq!(ctype("f64", &structs), "ctypes.c_double");
        assert_eq!(ctype("[u8; 32]", &structs), "ctypes.c_uint8 * 32");
        assert_eq!(
            ctype("[[f32; 2]; 512]", &structs),
            "(ctypes.c_float * 2) * 512"
        );
        assert_eq!(ctype("[Square; 2048]", &structs), "Square * 2048");
    }

    #[test]
    fn python_module_defines_structs_before_use_and_every_topic() {
        let text = python_ctypes();
        let at = |needle: &str| text.find(needle).unwrap_or(usize::MAX);
        assert!(at("class Square(") < at("class WorldMap("));
        assert!(at("class Header(") < at("class Pose("));
        assert!(at("class TopicStats(") < at("class Stats("));
        for t in all() {
            assert!(text.contains(&format!("return \"{}\"", t.type_name)));
        }
        assert!(text.contains("return f\"mole/{namespace}/{topic}\""));
    }

    #[test]
    fn every_message_constant_is_exported() {
        let ours: Vec<String> = constants().into_iter().map(|(name, _)| name).collect();
        for line in include_str!("messages.rs").lines() {
            if let Some(rest) = line.strip_prefix("pub const ")
                && !rest.starts_with("fn ")
                && let Some((name, _)) = rest.split_once(':')
            {
                assert!(
                    ours.iter().any(|n| n == name),
                    "layout::constants() misses {name}"
                );
            }
        }
    }
}
