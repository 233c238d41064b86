//! The stack's controls as Foxglove sees them: the settings `mole param` reads and changes as
//! Foxglove parameters (`ROLE.KEY`, e.g. `planning.apf.k_att`), and `mole swap`, `mole stop`
//! and `mole status` as services. Each goes to the launcher through `stack/control`, as the
//! commands do, on a thread of its own (a setting takes effect at the process's next step, which
//! the server's loop must not hold up).

use foxglove::Schema;
use foxglove::websocket::service::{Service, ServiceSchema};
use foxglove::websocket::{
    AnyClient, GetParametersResponder, Parameter, ParameterHandler, ParameterValue,
    SetParametersResponder,
};
use mole_runtime::ControlClient;
use mole_types::graph::GRAPH;
use mole_types::{
    CONTROL_OK, CONTROL_PARAM, CONTROL_STATUS, CONTROL_STOP, ControlRequest, read_name,
};
use serde::Deserialize;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// How long a request waits for the launcher: a setting is taken at the process's next step.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(10);

/// The services, by name.
pub const SWAP_SERVICE: &str = "/mole/swap";
pub const STOP_SERVICE: &str = "/mole/stop";
pub const STATUS_SERVICE: &str = "/mole/status";

/// The launcher of `namespace`, or why not.
fn launcher(namespace: &str) -> Result<ControlClient, String> {
    ControlClient::connect(namespace).map_err(|e| e.to_string())
}

/// One request to the launcher: the text of its answer, or why not.
fn call(client: &ControlClient, request: ControlRequest) -> Result<String, String> {
    let response = client
        .call(request, ANSWER_TIMEOUT)
        .map_err(|e| e.to_string())?;
    let text = read_name(&response.text).into_owned();
    match response.status {
        CONTROL_OK => Ok(text),
        _ => Err(text),
    }
}

/// `mole param WORDS…`.
fn param(client: &ControlClient, words: &[&str]) -> Result<String, String> {
    let mut request = ControlRequest::new(CONTROL_PARAM);
    if !request.set_argv(words) {
        return Err("the key or value is too long".to_string());
    }
    call(client, request)
}

/// A setting's text as a Foxglove value: a boolean, a number or else the text.
pub fn parameter(name: String, text: &str) -> Parameter {
    let value = match text {
        "true" => ParameterValue::Bool(true),
        "false" => ParameterValue::Bool(false),
        _ => match text.parse::<f64>() {
            Ok(number) if number.is_finite() => ParameterValue::Float64(number),
            _ => ParameterValue::String(text.to_string()),
        },
    };
    Parameter {
        name,
        r#type: None,
        value: Some(value),
    }
}

/// A Foxglove value as the text `mole param set` takes; `None` for an array, a map or none.
pub fn setting_text(value: &ParameterValue) -> Option<String> {
    match value {
        ParameterValue::Bool(b) => Some(b.to_string()),
        ParameterValue::Integer(i) => Some(i.to_string()),
        ParameterValue::Float64(x) => Some(x.to_string()),
        ParameterValue::String(s) => Some(s.clone()),
        _ => None,
    }
}

/// The settings of `role` from `mole param list`'s lines (`KEY = VALUE`, `  (fixed)` after a
/// key that cannot change while the process runs).
pub fn listed(role: &str, text: &str) -> Vec<Parameter> {
    text.lines()
        .filter_map(|line| {
            let (key, value) = line.split_once(" = ")?;
            let value = value.trim_end_matches("(fixed)").trim_end();
            Some(parameter(format!("{role}.{key}"), value))
        })
        .collect()
}

/// The settings as Foxglove parameters; `controls` off makes them read-only.
pub struct Settings {
    namespace: String,
    controls: bool,
    /// The roles that have settings, once the launcher said (it refuses the others).
    roles: Arc<Mutex<Option<Vec<&'static str>>>>,
}

impl Settings {
    pub fn new(namespace: &str, controls: bool) -> Settings {
        Settings {
            namespace: namespace.to_string(),
            controls,
            roles: Arc::default(),
        }
    }
}

/// Every setting of the stack in force, of the roles that have any (asked of every role the
/// first time).
fn all_settings(namespace: &str, roles: &Mutex<Option<Vec<&'static str>>>) -> Vec<Parameter> {
    let Ok(client) = launcher(namespace) else {
        return Vec::new();
    };
    let known = roles.lock().ok().and_then(|r| r.clone());
    let asked = known.unwrap_or_else(|| GRAPH.iter().map(|s| s.role.name()).collect());
    let (mut settings, mut answered) = (Vec::new(), Vec::new());
    for role in asked {
        if let Ok(text) = param(&client, &["list", role]) {
            settings.extend(listed(role, &text));
            answered.push(role);
        }
    }
    if let Ok(mut roles) = roles.lock() {
        roles.get_or_insert(answered);
    }
    settings
}

impl ParameterHandler for Settings {
    fn get(
        &self,
        _client: AnyClient,
        names: Vec<String>,
        _request_id: Option<String>,
        responder: GetParametersResponder,
    ) {
        let (namespace, roles) = (self.namespace.clone(), self.roles.clone());
        std::thread::spawn(move || {
            let all = all_settings(&namespace, &roles);
            responder.respond(
                all.into_iter()
                    .filter(|p| names.is_empty() || names.contains(&p.name))
                    .collect(),
            );
        });
    }

    fn set(
        &self,
        _client: AnyClient,
        parameters: Vec<Parameter>,
        _request_id: Option<String>,
        responder: SetParametersResponder,
    ) {
        let (namespace, controls) = (self.namespace.clone(), self.controls);
        let roles = self.roles.clone();
        std::thread::spawn(move || {
            let client = launcher(&namespace);
            let mut names = Vec::new();
            for p in parameters {
                let (Some((role, key)), Some(text)) = (
                    p.name.split_once('.'),
                    p.value.as_ref().and_then(setting_text),
                ) else {
                    tracing::warn!(
                        name = p.name,
                        "refused a parameter: expected ROLE.KEY and a value"
                    );
                    continue;
                };
                if !controls {
                    tracing::warn!(
                        name = p.name,
                        "refused a parameter: served with --no-controls"
                    );
                } else if let Err(why) = client
                    .as_ref()
                    .map_err(Clone::clone)
                    .and_then(|c| param(c, &["set", role, key, &text]))
                {
                    tracing::warn!(name = p.name, %why, "the stack refused a parameter");
                }
                names.push(p.name);
            }
            // The values in force afterwards: a refused change shows the value it left.
            let all = all_settings(&namespace, &roles);
            responder.respond(
                all.into_iter()
                    .filter(|p| names.contains(&p.name))
                    .collect(),
            );
        });
    }
}

/// `/mole/swap`'s request: the role and the new command, program first.
#[derive(Debug, Deserialize)]
struct SwapRequest {
    role: String,
    command: Vec<String>,
}

/// A service's JSON schema (request or response).
fn json_schema(name: &str, text: &'static str) -> Schema {
    Schema::new(name, "jsonschema", text.as_bytes())
}

/// `/mole/swap`, `/mole/stop` and `/mole/status` (JSON in, the launcher's answer as a JSON
/// string out; a refusal is the call's error).
pub fn services(namespace: &str) -> Vec<Service> {
    const ANSWER: &str = r#"{"type":"string","description":"the launcher's answer"}"#;
    const SWAP: &str = r#"{"type":"object","properties":{"role":{"type":"string"},"command":{"type":"array","items":{"type":"string"}}},"required":["role","command"]}"#;
    const NOTHING: &str = r#"{"type":"object"}"#;
    let schema = |name: &str, request: &'static str| {
        ServiceSchema::new(name)
            .with_request("json", json_schema(&format!("{name}.request"), request))
            .with_response("json", json_schema(&format!("{name}.response"), ANSWER))
    };
    let answer = |text: String| serde_json::Value::String(text).to_string().into_bytes();
    let ns = namespace.to_string();
    let swap = Service::builder(SWAP_SERVICE, schema("mole.Swap", SWAP)).blocking_handler_fn(
        move |request| {
            let swap: SwapRequest = serde_json::from_slice(request.payload())
                .map_err(|e| format!("expected {{\"role\":..,\"command\":[..]}}: {e}"))?;
            let cwd = std::env::current_dir().map_err(|e| e.to_string())?;
            let request =
                ControlRequest::swap(&swap.role, &cwd.display().to_string(), &swap.command)?;
            call(&launcher(&ns)?, request).map(answer)
        },
    );
    let ns = namespace.to_string();
    let stop = Service::builder(STOP_SERVICE, schema("mole.Stop", NOTHING)).blocking_handler_fn(
        move |_| call(&launcher(&ns)?, ControlRequest::new(CONTROL_STOP)).map(answer),
    );
    let ns = namespace.to_string();
    let status = Service::builder(STATUS_SERVICE, schema("mole.Status", NOTHING))
        .blocking_handler_fn(move |_| {
            call(&launcher(&ns)?, ControlRequest::new(CONTROL_STATUS)).map(answer)
        });
    vec![swap, stop, status]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_listed_setting_is_a_parameter_of_its_type() {
        let text = "planner = frontier  (fixed)\napf.k_att = 1.5\nsmooth = true\nname = a b";
        let params = listed("planning", text);
        let value = |i: usize| params[i].value.clone().unwrap();
        assert_eq!(params.len(), 4);
        assert_eq!(params[0].name, "planning.planner");
        assert_eq!(value(0), ParameterValue::String("frontier".into()));
        assert_eq!(params[1].name, "planning.apf.k_att");
        assert_eq!(value(1), ParameterValue::Float64(1.5));
        assert_eq!(value(2), ParameterValue::Bool(true));
        assert_eq!(value(3), ParameterValue::String("a b".into()));
    }

    #[test]
    fn a_value_goes_back_as_the_text_it_came_from() {
        for text in ["1.5", "true", "frontier", "-3", "0.001"] {
            let p = parameter("x.y".into(), text);
            assert_eq!(
                setting_text(p.value.as_ref().unwrap()).as_deref(),
                Some(text)
            );
        }
        assert_eq!(
            setting_text(&ParameterValue::Integer(7)).as_deref(),
            Some("7")
        );
        assert_eq!(setting_text(&ParameterValue::Array(vec![])), None);
    }
}
