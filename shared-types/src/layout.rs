//! The layout table: every message type's name, size, alignment and field offsets.
//!
//! `docs/messages.md` is generated from [`markdown`] and a test checks that it matches, so the
//! document other languages code against cannot drift from the Rust types. Sizes are asserted at
//! compile time below; `bytemuck::Pod` already refuses any implicit padding.

use crate::geometry::*;
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

fn field<T, F>(name: &'static str, offset: usize, _project: fn(&T) -> &F) -> FieldLayout {
    FieldLayout {
        name,
        offset,
        size: size_of::<F>(),
        ty: short_type_name(core::any::type_name::<F>()),
    }
}

macro_rules! layout {
    ($t:ident, $type_name:expr; $($f:ident),+ $(,)?) => {
        TypeLayout {
            rust_name: stringify!($t),
            type_name: $type_name,
            size: size_of::<$t>(),
            align: align_of::<$t>(),
            fields: vec![$(field::<$t, _>(stringify!($f), offset_of!($t, $f), |m: &$t| &m.$f)),+],
        }
    };
}

fn type_name<T: iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend>() -> &'static str {
    // SAFETY: `type_name` only returns the `#[type_name]` literal of the derive.
    unsafe { <T as iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend>::type_name() }
}

/// Every type that crosses a process boundary: the messages, then the structs they embed.
pub fn all() -> Vec<TypeLayout> {
    vec![
        layout!(Header, type_name::<Header>(); seq, tick, stamp_ns, origin_ns),
        layout!(WorldMap, type_name::<WorldMap>();
            header, arena_width, arena_height, dt, seed, start_x, start_y, start_theta, goal_x,
            goal_y, goal_tolerance, has_goal, n_obstacles, n_beacons, _pad, grid_resolution, robot,
            sensors, obstacles, beacons),
        layout!(Truth, type_name::<Truth>();
            header, x, y, theta, v, omega, penetration, cmd_latency_ns, flags, end_reason,
            n_contacts, _pad, contacts),
        layout!(Scan, type_name::<Scan>(); header, angle_min, angle_increment, range_max, n_beams, ranges),
        layout!(Tactile, type_name::<Tactile>(); header, n_sensors, radius, sensors),
        layout!(Odom, type_name::<Odom>(); header, v, omega, dt),
        layout!(Beacons, type_name::<Beacons>(); header, n_readings, _pad, readings),
        layout!(Fix, type_name::<Fix>(); header, x, y, std, valid, _pad),
        layout!(Pose, type_name::<Pose>(); header, x, y, theta, covariance, update_ns, estimator, _pad),
        layout!(Particles, type_name::<Particles>(); header, n_particles, _pad, particles),
        layout!(Grid, type_name::<Grid>();
            header, width, height, resolution, origin_x, origin_y, kind, _pad, cells),
        layout!(Cmd, type_name::<Cmd>(); header, v, omega, mode, _pad),
        layout!(PlanStatus, type_name::<PlanStatus>();
            header, mode, flags, goal_x, goal_y, frontier_x, frontier_y, bounces, n_path, path),
        layout!(Tick, type_name::<Tick>(); header, dt, flags, mode),
        layout!(Stats, type_name::<Stats>();
            header, process, pid, n_topics, cpu_ns, max_rss_bytes, steps, topics),
        layout!(RunStatus, type_name::<RunStatus>();
            header, coverage, loop_p50_us, loop_p99_us, max_penetration_m, rmse_m, finished),
        layout!(Processes, type_name::<Processes>(); header, n_processes, _pad, processes),
        layout!(RobotSpec, type_name::<RobotSpec>(); radius, max_speed, max_omega, max_accel, max_alpha),
        layout!(SensorSpec, type_name::<SensorSpec>();
            lidar_beams, tactile_sensors, lidar_range_max, lidar_fov, lidar_range_std,
            tactile_stiffness, tactile_force_std, odom_v_std, odom_omega_std, beacon_range_max,
            beacon_range_std, beacon_bearing_std, fix_std, fix_period_ticks, _pad),
        layout!(Square, type_name::<Square>(); cx, cy, side),
        layout!(BeaconSite, type_name::<BeaconSite>(); x, y, id, _pad),
        layout!(Contact, type_name::<Contact>(); px, py, nx, ny, depth),
        layout!(TactileReading, type_name::<TactileReading>(); angle, fx, fy, _pad),
        layout!(BeaconReading, type_name::<BeaconReading>(); id, _pad, range, bearing),
        layout!(Particle, type_name::<Particle>(); x, y, theta, w),
        layout!(TopicStats, type_name::<TopicStats>();
            topic, direction, _pad, count, dropped, invalid, rate_hz, latency_p50_us,
            latency_p99_us, latency_max_us),
        layout!(ProcessStatus, type_name::<ProcessStatus>(); role, pid, state, restarts, _pad),
    ]
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
    for (topic, ty) in crate::topics::ALL {
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

// Compile-time size assertions: a layout change must be deliberate (bump the type_name version).
const _: () = {
    assert!(size_of::<Header>() == 32);
    assert!(size_of::<RobotSpec>() == 40);
    assert!(size_of::<SensorSpec>() == 104);
    assert!(size_of::<Square>() == 24);
    assert!(size_of::<BeaconSite>() == 24);
    assert!(size_of::<Contact>() == 40);
    assert!(size_of::<WorldMap>() == 280 + 24 * MAX_OBSTACLES + 24 * MAX_BEACONS);
    assert!(size_of::<Truth>() == 104 + 40 * MAX_CONTACTS);
    assert!(size_of::<Scan>() == 48 + 4 * MAX_BEAMS);
    assert!(size_of::<Tactile>() == 40 + 16 * MAX_TACTILE);
    assert!(size_of::<Odom>() == 56);
    assert!(size_of::<Beacons>() == 40 + 24 * MAX_BEACONS);
    assert!(size_of::<Fix>() == 64);
    assert!(size_of::<Pose>() == 144);
    assert!(size_of::<Particles>() == 40 + 16 * MAX_PARTICLES);
    assert!(size_of::<Grid>() == 72 + MAX_GRID_CELLS);
    assert!(size_of::<Cmd>() == 56);
    assert!(size_of::<PlanStatus>() == 80 + 8 * MAX_PATH);
    assert!(size_of::<Tick>() == 48);
    assert!(size_of::<TopicStats>() == 80);
    assert!(size_of::<Stats>() == 96 + 80 * MAX_TOPIC_STATS);
    assert!(size_of::<RunStatus>() == 56);
    assert!(size_of::<ProcessStatus>() == 48);
    assert!(size_of::<Processes>() == 40 + 48 * MAX_PROCESSES);
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
        let expected = markdown();
        if std::env::var_os("MOLE_BLESS").is_some() {
            std::fs::write(path, &expected).expect("write docs/messages.md");
        }
        let actual = std::fs::read_to_string(path).unwrap_or_default();
        assert!(
            actual == expected,
            "docs/messages.md differs from the code: regenerate it with \
             `MOLE_BLESS=1 cargo test -p mole-types` and review the diff"
        );
    }
}
