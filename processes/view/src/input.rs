//! What a page may send: a goal (a click on the map) or a pace (pause, run, step a lockstep
//! run) to a live stack, a timeline op (play, pause, seek, speed) to a recording. Anything else,
//! and an input the view's [`Access`] does not take, is refused with the reason, which the
//! server counts and logs.

use serde::Deserialize;

/// The longest input accepted (bytes); the server also caps WebSocket messages at this size.
pub const MAX_INPUT_BYTES: usize = 4096;
/// The most steps one `step` may ask for: what `operator/pace` allows.
pub const MAX_STEPS: u32 = mole_types::PACE_MAX_STEPS;

/// A valid input from a page.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PageInput {
    /// Go to (x, y) (m, world frame).
    Goal { x: f64, y: f64 },
    /// Run freely.
    Run,
    /// Hold the world before its next step.
    Pause,
    /// Take `steps` more steps, then hold.
    Step { steps: u32 },
    /// Move a recording's playback.
    Timeline(TimelineOp),
}

/// What a page may do to a recording's playback.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TimelineOp {
    Play,
    Pause,
    /// Go to a tick (clamped to the recording's).
    Seek {
        tick: u64,
    },
    /// Play this many times as fast as recorded, in [`MIN_SPEED`, `MAX_SPEED`].
    Speed {
        speed: f64,
    },
}

/// The slowest and fastest playback (× the recorded simulated time).
pub const MIN_SPEED: f64 = 0.1;
pub const MAX_SPEED: f64 = 20.0;

/// What the view takes from its pages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// A live stack: goals and paces, unless `controls` is off; no timeline.
    Live { controls: bool },
    /// A recording: timeline ops only (nothing steers a recorded robot).
    Recording,
}

/// Why an input was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Rejected {
    #[error("input of {0} bytes is longer than {MAX_INPUT_BYTES}")]
    TooLong(usize),
    #[error("not JSON of a known input: {0}")]
    Malformed(String),
    #[error("unknown pace `{0}` (pause, run or step)")]
    UnknownPace(String),
    #[error("unknown timeline op `{0}` (play, pause, seek or speed)")]
    UnknownTimelineOp(String),
    #[error("steps {0} outside 1..={MAX_STEPS}")]
    Steps(u64),
    #[error("steps given with pace `{0}`, which takes none")]
    StepsWithout(String),
    #[error("the view was started with --no-controls")]
    ControlsOff,
    #[error("binary input (the view takes JSON text)")]
    Binary,
    #[error("a WebSocket message over {MAX_INPUT_BYTES} bytes (its connection is closed)")]
    Oversized,
    #[error("speed {0} outside {MIN_SPEED}..={MAX_SPEED}")]
    Speed(f64),
    #[error(
        "timeline op `{0}` with the wrong fields (play, pause; seek with a tick; speed with a \
         speed)"
    )]
    TimelineFields(String),
    #[error("a timeline op, but the view shows a live stack, not a recording")]
    NotRecording,
    #[error("a goal or pace, but the view shows a recording (only timeline ops)")]
    Recording,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Point {
    x: f64,
    y: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields, untagged)]
enum Input {
    Goal { goal: Point },
    Pace { pace: String, steps: Option<u64> },
    Timeline { timeline: Timeline },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Timeline {
    op: String,
    tick: Option<u64>,
    speed: Option<f64>,
}

/// A timeline op from its fields: each op takes its own and no other.
fn timeline_op(timeline: Timeline) -> Result<TimelineOp, Rejected> {
    let Timeline { op, tick, speed } = timeline;
    match (op.as_str(), tick, speed) {
        ("play", None, None) => Ok(TimelineOp::Play),
        ("pause", None, None) => Ok(TimelineOp::Pause),
        ("seek", Some(tick), None) => Ok(TimelineOp::Seek { tick }),
        ("speed", None, Some(speed)) if (MIN_SPEED..=MAX_SPEED).contains(&speed) => {
            Ok(TimelineOp::Speed { speed })
        }
        ("speed", None, Some(speed)) => Err(Rejected::Speed(speed)),
        ("play" | "pause" | "seek" | "speed", ..) => Err(Rejected::TimelineFields(op)),
        _ => Err(Rejected::UnknownTimelineOp(op)),
    }
}

/// Parses one input: `{"goal":{"x":X,"y":Y}}`, `{"pace":"pause"|"run"}`,
/// `{"pace":"step","steps":N}` (N defaults to 1), or `{"timeline":{"op":"play"|"pause"}}`,
/// `{"timeline":{"op":"seek","tick":N}}`, `{"timeline":{"op":"speed","speed":X}}`.
pub fn parse_input(text: &str) -> Result<PageInput, Rejected> {
    if text.len() > MAX_INPUT_BYTES {
        return Err(Rejected::TooLong(text.len()));
    }
    let input: Input = serde_json::from_str(text).map_err(|e| {
        // serde's message for an untagged enum names neither form; say what is expected.
        let why = match e.classify() {
            serde_json::error::Category::Data => {
                "expected {\"goal\":{\"x\":..,\"y\":..}}, {\"pace\":..} or {\"timeline\":{\"op\":..}}"
                    .to_string()
            }
            _ => e.to_string(),
        };
        Rejected::Malformed(why)
    })?;
    match input {
        // JSON has no NaN or infinity, and serde_json refuses a number beyond f64's range.
        Input::Goal { goal } => Ok(PageInput::Goal {
            x: goal.x,
            y: goal.y,
        }),
        Input::Pace { pace, steps } => match (pace.as_str(), steps) {
            ("step", None) => Ok(PageInput::Step { steps: 1 }),
            ("step", Some(n)) if (1..=u64::from(MAX_STEPS)).contains(&n) => {
                Ok(PageInput::Step { steps: n as u32 })
            }
            ("step", Some(n)) => Err(Rejected::Steps(n)),
            ("run" | "pause", Some(_)) => Err(Rejected::StepsWithout(pace)),
            ("run", None) => Ok(PageInput::Run),
            ("pause", None) => Ok(PageInput::Pause),
            _ => Err(Rejected::UnknownPace(pace)),
        },
        Input::Timeline { timeline } => timeline_op(timeline).map(PageInput::Timeline),
    }
}

/// Whether a view of `access` takes `command`: a live view goals and paces (while its controls
/// are on), a recording's view timeline ops.
pub fn admit(command: PageInput, access: Access) -> Result<PageInput, Rejected> {
    match (command, access) {
        (PageInput::Timeline(_), Access::Recording) => Ok(command),
        (PageInput::Timeline(_), Access::Live { .. }) => Err(Rejected::NotRecording),
        (_, Access::Recording) => Err(Rejected::Recording),
        (_, Access::Live { controls: false }) => Err(Rejected::ControlsOff),
        (_, Access::Live { controls: true }) => Ok(command),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every valid form parses to its command.
    #[test]
    fn goals_and_paces_parse() {
        assert_eq!(
            parse_input(r#"{"goal":{"x":1.5,"y":-2}}"#),
            Ok(PageInput::Goal { x: 1.5, y: -2.0 })
        );
        assert_eq!(parse_input(r#"{"pace":"pause"}"#), Ok(PageInput::Pause));
        assert_eq!(parse_input(r#"{"pace":"run"}"#), Ok(PageInput::Run));
        assert_eq!(
            parse_input(r#"{"pace":"step"}"#),
            Ok(PageInput::Step { steps: 1 })
        );
        assert_eq!(
            parse_input(r#"{"pace":"step","steps":25}"#),
            Ok(PageInput::Step { steps: 25 })
        );
    }

    /// Every timeline op parses, the speed's bounds included.
    #[test]
    fn timeline_ops_parse() {
        let op = |text: &str| {
            parse_input(text).map(|c| match c {
                PageInput::Timeline(op) => op,
                other => panic!("{text} parsed to {other:?}"),
            })
        };
        assert_eq!(op(r#"{"timeline":{"op":"play"}}"#), Ok(TimelineOp::Play));
        assert_eq!(op(r#"{"timeline":{"op":"pause"}}"#), Ok(TimelineOp::Pause));
        assert_eq!(
            op(r#"{"timeline":{"op":"seek","tick":420}}"#),
            Ok(TimelineOp::Seek { tick: 420 })
        );
        assert_eq!(
            op(r#"{"timeline":{"op":"speed","speed":0.1}}"#),
            Ok(TimelineOp::Speed { speed: 0.1 })
        );
        assert_eq!(
            op(r#"{"timeline":{"op":"speed","speed":20}}"#),
            Ok(TimelineOp::Speed { speed: 20.0 })
        );
    }

    /// A live view takes goals and paces (controls on) but no timeline op; a recording's view
    /// takes timeline ops only.
    #[test]
    fn each_view_admits_only_its_own_inputs() {
        let goal = PageInput::Goal { x: 1.0, y: 2.0 };
        let seek = PageInput::Timeline(TimelineOp::Seek { tick: 3 });
        let live = Access::Live { controls: true };
        assert_eq!(admit(goal, live), Ok(goal));
        assert_eq!(admit(PageInput::Pause, live), Ok(PageInput::Pause));
        assert_eq!(admit(seek, live), Err(Rejected::NotRecording));
        let watching = Access::Live { controls: false };
        assert_eq!(admit(goal, watching), Err(Rejected::ControlsOff));
        assert_eq!(admit(seek, watching), Err(Rejected::NotRecording));
        assert_eq!(admit(seek, Access::Recording), Ok(seek));
        assert_eq!(admit(goal, Access::Recording), Err(Rejected::Recording));
        assert_eq!(
            admit(PageInput::Step { steps: 2 }, Access::Recording),
            Err(Rejected::Recording)
        );
    }

    /// Every malformed kind is refused with its own reason, never accepted.
    #[test]
    fn every_malformed_kind_is_refused() {
        let malformed = |text: &str| matches!(parse_input(text), Err(Rejected::Malformed(_)));
        assert!(malformed("not json"));
        assert!(malformed(""));
        assert!(malformed("[1,2]"));
        assert!(malformed(r#"{"goal":{"x":1}}"#), "a missing field");
        assert!(malformed(r#"{"goal":{"x":"1","y":2}}"#), "a string number");
        assert!(
            malformed(r#"{"goal":{"x":1,"y":2,"z":3}}"#),
            "an unknown field"
        );
        assert!(malformed(r#"{"teleport":{"x":1,"y":2}}"#), "an unknown op");
        assert!(malformed(r#"{"goal":{"x":NaN,"y":2}}"#), "NaN is no JSON");
        assert!(
            malformed(r#"{"goal":{"x":1e999,"y":2}}"#),
            "out of f64's range"
        );
        assert!(malformed(r#"{"pace":"step","steps":-1}"#));
        assert_eq!(
            parse_input(r#"{"pace":"rewind"}"#),
            Err(Rejected::UnknownPace("rewind".into()))
        );
        assert_eq!(
            parse_input(r#"{"pace":"step","steps":0}"#),
            Err(Rejected::Steps(0))
        );
        assert_eq!(
            parse_input(r#"{"pace":"step","steps":100001}"#),
            Err(Rejected::Steps(100_001))
        );
        assert_eq!(
            parse_input(r#"{"pace":"run","steps":3}"#),
            Err(Rejected::StepsWithout("run".into()))
        );
        assert!(malformed(r#"{"timeline":{"op":"seek","tick":-3}}"#));
        assert!(
            malformed(r#"{"timeline":{"op":"play","at":3}}"#),
            "an unknown field"
        );
        assert!(malformed(r#"{"timeline":"play"}"#));
        assert_eq!(
            parse_input(r#"{"timeline":{"op":"rewind"}}"#),
            Err(Rejected::UnknownTimelineOp("rewind".into()))
        );
        let wrong_fields =
            |text: &str| matches!(parse_input(text), Err(Rejected::TimelineFields(_)));
        assert!(
            wrong_fields(r#"{"timeline":{"op":"seek"}}"#),
            "seek without a tick"
        );
        assert!(wrong_fields(r#"{"timeline":{"op":"play","tick":3}}"#));
        assert!(wrong_fields(r#"{"timeline":{"op":"speed","tick":3}}"#));
        assert_eq!(
            parse_input(r#"{"timeline":{"op":"speed","speed":50}}"#),
            Err(Rejected::Speed(50.0))
        );
        assert_eq!(
            parse_input(r#"{"timeline":{"op":"speed","speed":0.05}}"#),
            Err(Rejected::Speed(0.05))
        );
        let long = format!(
            r#"{{"pace":"run","pad":"{}"}}"#,
            "x".repeat(MAX_INPUT_BYTES)
        );
        assert_eq!(parse_input(&long), Err(Rejected::TooLong(long.len())));
    }
}
