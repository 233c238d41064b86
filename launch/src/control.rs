//! `mole swap`, `mole stop`, `mole status`: one request each to a running `mole up`, through
//! its `stack/control` request-response service.

use crate::Failure;
use crate::swap::split_words;
use clap::Args;
use mole_runtime::ControlClient;
use mole_types::{
    CONTROL_OK, CONTROL_REFUSED, CONTROL_STATUS, CONTROL_STOP, ControlRequest, ControlResponse,
    read_name,
};
use std::time::Duration;

#[derive(Debug, Clone, Args)]
pub struct SwapArgs {
    /// Namespace of the running stack.
    #[arg(long, default_value = mole_types::env::DEFAULT_NAMESPACE)]
    pub namespace: String,
    /// How long to wait for the swap (s).
    #[arg(long, default_value_t = 60.0)]
    pub timeout: f64,
    /// The role to replace: sensing, localization, mapping or planning.
    pub role: String,
    /// The new command, quoted when it has arguments ("mole-planning --planner apf"); it is
    /// split like a shell would split it. Options of `mole swap` may follow it.
    #[arg(required = true)]
    pub command: Vec<String>,
}

#[derive(Debug, Clone, Args)]
pub struct NamespaceArgs {
    /// Namespace of the running stack.
    #[arg(long, default_value = mole_types::env::DEFAULT_NAMESPACE)]
    pub namespace: String,
}

pub(crate) fn call(
    namespace: &str,
    request: ControlRequest,
    timeout: f64,
) -> Result<ControlResponse, Failure> {
    if !(timeout.is_finite() && timeout > 0.0) {
        return Err(Failure::input(format!(
            "--timeout: expected a positive number of seconds, found {timeout}"
        )));
    }
    // A stack that is not there is a wrong namespace: bad input.
    let client = ControlClient::connect(namespace).map_err(|e| Failure::input(e.to_string()))?;
    client
        .call(request, Duration::from_secs_f64(timeout))
        .map_err(|e| Failure::run(e.to_string()))
}

pub(crate) fn answer(response: &ControlResponse) -> Result<String, Failure> {
    let text = read_name(&response.text).into_owned();
    match response.status {
        CONTROL_OK => Ok(text),
        CONTROL_REFUSED => Err(Failure::input(text)),
        _ => Err(Failure::run(text)),
    }
}

/// `mole swap ROLE COMMAND...`: prints the launcher's report (the gap, lost and repeated steps).
pub fn swap(args: &SwapArgs) -> Result<(), Failure> {
    let argv = match args.command.as_slice() {
        [one] => split_words(one).map_err(|e| Failure::input(format!("COMMAND: {e}")))?,
        words => words.to_vec(),
    };
    let cwd = std::env::current_dir()
        .map_err(|e| Failure::run(format!("cannot read the current directory: {e}")))?;
    let request = ControlRequest::swap(&args.role, &cwd.display().to_string(), &argv)
        .map_err(Failure::input)?;
    let response = call(&args.namespace, request, args.timeout)?;
    println!("{}", answer(&response)?);
    Ok(())
}

/// `mole stop`: the running stack stops as on Ctrl-C and writes its summary.
pub fn stop(args: &NamespaceArgs) -> Result<(), Failure> {
    let request = ControlRequest::new(CONTROL_STOP);
    println!("{}", answer(&call(&args.namespace, request, 10.0)?)?);
    Ok(())
}

/// `mole status`: one line on the running stack.
pub fn status(args: &NamespaceArgs) -> Result<(), Failure> {
    let request = ControlRequest::new(CONTROL_STATUS);
    println!("{}", answer(&call(&args.namespace, request, 10.0)?)?);
    Ok(())
}
