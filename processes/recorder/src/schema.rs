//! The schema of a recorded channel: the message's layout as JSON (schema encoding
//! [`SCHEMA_ENCODING`]), taken from the one layout table (`mole_types::layout`, which also makes
//! docs/messages.md), so any MCAP reader can decode the payload without mole's code.
//!
//! ```json
//! { "type_name": "mole.Truth.v1", "rust_name": "Truth", "size": 424, "align": 8,
//!   "byte_order": "little",
//!   "fields": [ { "name": "header", "offset": 0, "size": 32, "type": "Header" },
//!               { "name": "x", "offset": 32, "size": 8, "type": "f64" }, ... ],
//!   "structs": { "Header": { "type_name": "mole.Header.v1", "size": 32, "align": 8,
//!                            "fields": [ ... ] }, ... } }
//! ```
//!
//! A field's `type` is a primitive (`u8` … `u64`, `i8` … `i64`, `f32`, `f64`), a struct named in
//! `structs` (every struct the message embeds, at any depth), or an array `[T; N]` of either.

use mole_types::layout::{self, TypeLayout};
use serde_json::{Value, json};

/// The schema encoding of every message channel: this module's JSON layout.
pub const SCHEMA_ENCODING: &str = "mole-layout";
/// The message encoding of every message channel: the message's own `#[repr(C)]` bytes,
/// little-endian, exactly `size` bytes.
pub const MESSAGE_ENCODING: &str = "mole-layout";

/// The schema of the message type `type_name` (`mole.Truth.v1`); `None` for a type the layout
/// table does not have.
pub fn schema_json(type_name: &str) -> Option<String> {
    let types = layout::all();
    let message = types.iter().find(|t| t.type_name == type_name)?;
    let mut structs = serde_json::Map::new();
    embedded_structs(message, &types, &mut structs);
    let mut schema = describe(message);
    schema["rust_name"] = json!(message.rust_name);
    schema["byte_order"] = json!("little");
    schema["structs"] = Value::Object(structs);
    Some(schema.to_string())
}

/// Size, alignment and field table of one type.
fn describe(t: &TypeLayout) -> Value {
    let fields: Vec<Value> = t
        .fields
        .iter()
        .map(|f| json!({ "name": f.name, "offset": f.offset, "size": f.size, "type": f.ty }))
        .collect();
    json!({ "type_name": t.type_name, "size": t.size, "align": t.align, "fields": fields })
}

/// Adds every struct `t`'s fields name, and the structs those name, to `out`.
fn embedded_structs(
    t: &TypeLayout,
    types: &[TypeLayout],
    out: &mut serde_json::Map<String, Value>,
) {
    for field in &t.fields {
        for word in field.ty.split(|c: char| !(c.is_alphanumeric() || c == '_')) {
            if let Some(inner) = types.iter().find(|s| s.rust_name == word)
                && !out.contains_key(word)
            {
                out.insert(word.to_string(), describe(inner));
                embedded_structs(inner, types, out);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mole_types::topics;

    fn parsed(type_name: &str) -> Value {
        let text = schema_json(type_name).expect("a schema");
        serde_json::from_str(&text).expect("valid JSON")
    }

    /// The field a schema lists under `name`.
    fn field<'a>(schema: &'a Value, name: &str) -> &'a Value {
        schema["fields"]
            .as_array()
            .and_then(|f| f.iter().find(|f| f["name"] == name))
            .unwrap_or_else(|| panic!("no field {name} in {schema}"))
    }

    /// The truth's schema places x, y and θ where the Rust type has them, and carries the
    /// header's own table, so a reader finds the tick without mole's code.
    #[test]
    fn the_truth_schema_locates_the_pose_and_the_tick() {
        let schema = parsed("mole.Truth.v1");
        assert_eq!(schema["size"], size_of::<mole_types::Truth>());
        assert_eq!(schema["byte_order"], "little");
        for (name, offset) in [
            ("x", core::mem::offset_of!(mole_types::Truth, x)),
            ("y", core::mem::offset_of!(mole_types::Truth, y)),
            ("theta", core::mem::offset_of!(mole_types::Truth, theta)),
        ] {
            assert_eq!(field(&schema, name)["offset"], offset);
            assert_eq!(field(&schema, name)["type"], "f64");
        }
        let header = &schema["structs"]["Header"];
        assert_eq!(
            field(header, "tick")["offset"],
            core::mem::offset_of!(mole_types::Header, tick)
        );
    }

    /// Every recorded topic has a schema, and every struct a schema's fields name (at any
    /// depth: the world map's robot and sensors) is in it.
    #[test]
    fn every_topic_has_a_self_contained_schema() {
        for (topic, type_name) in topics::all() {
            let schema = parsed(type_name);
            let structs = schema["structs"].as_object().expect("structs");
            let mut tables = vec![&schema];
            tables.extend(structs.values());
            for table in tables {
                for f in table["fields"].as_array().expect("fields") {
                    let ty = f["type"].as_str().expect("type");
                    let element = ty
                        .trim_start_matches('[')
                        .split([';', ']'])
                        .next()
                        .unwrap_or(ty);
                    let primitive = matches!(
                        element,
                        "u8" | "u16" | "u32" | "u64" | "i8" | "i16" | "i32" | "i64" | "f32" | "f64"
                    );
                    assert!(
                        primitive || structs.contains_key(element),
                        "{topic}: `{ty}` is neither a primitive nor in structs"
                    );
                }
            }
        }
        assert!(parsed("mole.WorldMap.v1")["structs"]["SensorSpec"].is_object());
        assert_eq!(schema_json("mole.NoSuchType.v1"), None);
    }
}
