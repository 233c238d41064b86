//! What a client may publish (the protocol's client publishing): the view page's inputs on
//! [`OPERATOR_CHANNEL`] (a goal, a pace), and a goal from Foxglove's 3D panel, which publishes
//! a clicked pose on [`POSE_GOAL_CHANNEL`] and a clicked point on [`POINT_GOAL_CHANNEL`], as
//! ROS-shaped JSON. Anything else is refused with the reason, and counted.

use mole_view::{Access, PageInput, Rejected, admit, parse_input};
use serde::Deserialize;

/// The page's inputs, as JSON text: `{"goal":{"x":..,"y":..}}`, `{"pace":"pause"|"run"}`,
/// `{"pace":"step","steps":N}`.
pub const OPERATOR_CHANNEL: &str = "/operator";
/// Foxglove's 3D panel's "publish pose" (`geometry_msgs/PoseStamped`): a goal at its position.
pub const POSE_GOAL_CHANNEL: &str = "/move_base_simple/goal";
/// Foxglove's 3D panel's "publish point" (`geometry_msgs/PointStamped`): a goal at the point.
pub const POINT_GOAL_CHANNEL: &str = "/clicked_point";
/// The message encoding a client publishes in.
pub const CLIENT_ENCODING: &str = "json";

/// Why a client's message was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Refused {
    #[error(
        "channel `{0}` takes nothing (publish on {OPERATOR_CHANNEL}, {POSE_GOAL_CHANNEL} or {POINT_GOAL_CHANNEL})"
    )]
    UnknownChannel(String),
    #[error("`{0}` messages, expected `{CLIENT_ENCODING}`")]
    Encoding(String),
    #[error("not UTF-8 JSON text")]
    NotText,
    #[error("not a {0}: {1}")]
    Malformed(&'static str, String),
    #[error(transparent)]
    Input(#[from] Rejected),
}

#[derive(Deserialize)]
struct Point {
    x: f64,
    y: f64,
}

#[derive(Deserialize)]
struct Pose {
    position: Point,
}

#[derive(Deserialize)]
struct PoseStamped {
    pose: Pose,
}

#[derive(Deserialize)]
struct PointStamped {
    point: Point,
}

/// The input a client's `payload` on `channel` (in `encoding`) is, if a stack with `controls`
/// takes it.
pub fn client_input(
    channel: &str,
    encoding: &str,
    payload: &[u8],
    controls: bool,
) -> Result<PageInput, Refused> {
    let known = [OPERATOR_CHANNEL, POSE_GOAL_CHANNEL, POINT_GOAL_CHANNEL];
    if !known.contains(&channel) {
        return Err(Refused::UnknownChannel(channel.to_string()));
    }
    if encoding != CLIENT_ENCODING {
        return Err(Refused::Encoding(encoding.to_string()));
    }
    let text = std::str::from_utf8(payload).map_err(|_| Refused::NotText)?;
    let malformed =
        |what: &'static str| move |e: serde_json::Error| Refused::Malformed(what, e.to_string());
    let input = match channel {
        POSE_GOAL_CHANNEL => {
            let p: PoseStamped = serde_json::from_str(text).map_err(malformed("PoseStamped"))?;
            goal(p.pose.position)
        }
        POINT_GOAL_CHANNEL => {
            let p: PointStamped = serde_json::from_str(text).map_err(malformed("PointStamped"))?;
            goal(p.point)
        }
        _ => parse_input(text)?,
    };
    Ok(admit(input, Access::Live { controls })?)
}

fn goal(p: Point) -> PageInput {
    PageInput::Goal { x: p.x, y: p.y }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pose_a_point_and_the_pages_inputs_are_goals_and_paces() {
        let pose = br#"{"header":{"frame_id":"map"},"pose":{"position":{"x":1.5,"y":-2,"z":0},"orientation":{"x":0,"y":0,"z":0,"w":1}}}"#;
        assert_eq!(
            client_input(POSE_GOAL_CHANNEL, "json", pose, true),
            Ok(PageInput::Goal { x: 1.5, y: -2.0 })
        );
        let point = br#"{"header":{},"point":{"x":3,"y":4,"z":0}}"#;
        assert_eq!(
            client_input(POINT_GOAL_CHANNEL, "json", point, true),
            Ok(PageInput::Goal { x: 3.0, y: 4.0 })
        );
        let step = br#"{"pace":"step","steps":5}"#;
        assert_eq!(
            client_input(OPERATOR_CHANNEL, "json", step, true),
            Ok(PageInput::Step { steps: 5 })
        );
    }

    #[test]
    fn malformed_or_unwanted_input_is_refused_with_the_reason() {
        let refused = |channel: &str, encoding: &str, payload: &[u8], controls: bool| {
            client_input(channel, encoding, payload, controls).unwrap_err()
        };
        assert!(matches!(
            refused("/cmd_vel", "json", b"{}", true),
            Refused::UnknownChannel(_)
        ));
        assert!(matches!(
            refused(OPERATOR_CHANNEL, "cdr", b"{}", true),
            Refused::Encoding(_)
        ));
        assert_eq!(
            refused(OPERATOR_CHANNEL, "json", &[0xff, 0xfe], true),
            Refused::NotText
        );
        assert!(matches!(
            refused(POSE_GOAL_CHANNEL, "json", br#"{"pose":{}}"#, true),
            Refused::Malformed("PoseStamped", _)
        ));
        assert!(matches!(
            refused(OPERATOR_CHANNEL, "json", br#"{"pace":"fly"}"#, true),
            Refused::Input(Rejected::UnknownPace(_))
        ));
        assert!(matches!(
            refused(
                OPERATOR_CHANNEL,
                "json",
                br#"{"timeline":{"op":"play"}}"#,
                true
            ),
            Refused::Input(Rejected::NotRecording)
        ));
        let pose = br#"{"pose":{"position":{"x":1,"y":2,"z":0}}}"#;
        assert_eq!(
            refused(POSE_GOAL_CHANNEL, "json", pose, false),
            Refused::Input(Rejected::ControlsOff)
        );
    }
}
