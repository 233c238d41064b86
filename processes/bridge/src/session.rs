//! The bridge's zenoh session: opened as the spec configures it; where it listens (port 0: the
//! port it got) logged and written to the run's output directory, where a restarted bridge reads
//! it to listen there again.

use crate::{BridgeSpec, Failed, LISTENING};
use mole_runtime::BadInput;
use mole_types::link::{Endpoint, LISTENING_FILE};
use std::path::{Path, PathBuf};
use zenoh::Wait;

/// The file in the run's output directory `out_dir` where the bridge writes where it listens
/// ([`LISTENING_FILE`]); a restarted bridge reads it and `spec` listens there again.
pub fn listen_again(spec: &mut BridgeSpec, out_dir: Option<&Path>) -> Option<PathBuf> {
    let listening = out_dir.map(|out| out.join(LISTENING_FILE));
    if let Some(again) = listening.as_deref().and_then(|file| recorded(spec, file)) {
        spec.listen = again;
    }
    listening
}

/// A restarted bridge's endpoints: where its first start listened (its port 0 resolved), read
/// from `file`, so the other half finds it there again.
fn recorded(spec: &BridgeSpec, file: &Path) -> Option<Vec<Endpoint>> {
    if spec.listen.iter().all(|e| e.port() != 0) {
        return None;
    }
    let recorded = std::fs::read_to_string(file).ok()?;
    let again = spec.listening_again(&recorded);
    match &again {
        Some(_) => tracing::info!(
            file = %file.display(),
            "listening again where the first start of this run did"
        ),
        None => tracing::warn!(
            file = %file.display(),
            "not the endpoints of this bridge: listening as configured"
        ),
    }
    again
}

/// The zenoh session `spec` configures (refused by zenoh: bad input); where it listens is
/// logged, replaces `spec.listen` (port 0 resolved) and is written to `listening`.
pub fn open_session(
    spec: &mut BridgeSpec,
    listening: Option<&Path>,
) -> Result<zenoh::Session, Failed> {
    let config = zenoh::Config::from_json5(&spec.zenoh_config().to_string())
        .map_err(|e| BadInput(format!("zenoh configuration: {e}")))?;
    let session = zenoh::open(config)
        .wait()
        .map_err(|e| BadInput(format!("cannot open the zenoh session: {e}")))?;
    report_listening(&session, spec, listening)?;
    Ok(session)
}

/// Logs where the session listens (port 0 replaced by the port zenoh bound), one
/// "listening on ENDPOINT" line each, and writes them to `file`, one a line, for the other
/// half (replaced whole: a reader never sees half of it).
fn report_listening(
    session: &zenoh::Session,
    spec: &mut BridgeSpec,
    file: Option<&Path>,
) -> Result<(), Failed> {
    if spec.listen.is_empty() {
        return Ok(());
    }
    let locators: Vec<String> = session
        .info()
        .locators()
        .wait()
        .iter()
        .map(ToString::to_string)
        .collect();
    let bound = spec.bound(&locators).ok_or_else(|| {
        BadInput(format!(
            "cannot tell which port zenoh bound for {}: it listens on {}",
            spec.whereabouts(),
            locators.join(", ")
        ))
    })?;
    for endpoint in &bound {
        tracing::info!("{LISTENING} {}", endpoint.as_str());
    }
    spec.listen = bound;
    if let Some(file) = file {
        let text: String = spec
            .listen
            .iter()
            .map(|e| format!("{}\n", e.as_str()))
            .collect();
        let partial = file.with_extension("partial");
        std::fs::write(&partial, text)
            .and_then(|()| std::fs::rename(&partial, file))
            .map_err(|e| BadInput(format!("cannot write {}: {e}", file.display())))?;
    }
    Ok(())
}
