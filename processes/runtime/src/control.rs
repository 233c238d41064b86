//! `stack/control`: the launcher serves it, `mole swap` / `mole stop` / `mole status` call it.
//! An iceoryx2 request-response service, like every other link of the stack (docs/architecture.md).

use crate::context::Context;
use crate::error::RuntimeError;
use crate::time::now_ns;
use iceoryx2::active_request::ActiveRequest;
use iceoryx2::port::client::Client;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::*;
use mole_types::topics::{RequestResponse, STACK_CONTROL};
use mole_types::{CONTROL_REFUSED, ControlRequest, ControlResponse, Message};
use std::time::{Duration, Instant};

type ControlService = iceoryx2::service::port_factory::request_response::PortFactory<
    ipc::Service,
    ControlRequest,
    (),
    ControlResponse,
    (),
>;

/// Opens (or, for the server, creates) the control service with the settings both sides use.
fn control_service(
    node: &Node<ipc::Service>,
    namespace: &str,
    create: bool,
) -> Result<ControlService, RuntimeError> {
    let service: RequestResponse<ControlRequest, ControlResponse> = STACK_CONTROL;
    let full = mole_types::topics::service_name(namespace, service.name);
    let name: ServiceName = full
        .as_str()
        .try_into()
        .map_err(|e| RuntimeError::Name(full.clone(), format!("{e:?}")))?;
    let builder = node
        .service_builder(&name)
        .request_response::<ControlRequest, ControlResponse>()
        .max_servers(1)
        .max_clients(4)
        .max_active_requests_per_client(1)
        .max_response_buffer_size(1);
    let failed = |reason: String| RuntimeError::Service {
        topic: service.name.to_string(),
        reason,
    };
    if create {
        builder
            .open_or_create()
            .map_err(|e| failed(format!("{e:?}")))
    } else {
        builder.open().map_err(|e| {
            let debug = format!("{e:?}");
            failed(if debug.contains("DoesNotExist") {
                format!("no stack is running in namespace `{namespace}` (nothing serves it)")
            } else {
                debug
            })
        })
    }
}

/// The launcher's end of `stack/control`.
pub struct ControlServer {
    server: Server<ipc::Service, ControlRequest, (), ControlResponse, ()>,
    invalid: u64,
}

/// One request being handled; answer it with [`ControlCall::respond`].
pub struct ControlCall {
    active: ActiveRequest<ipc::Service, ControlRequest, (), ControlResponse, ()>,
}

impl Context {
    /// Serves `stack/control` in this context's namespace (the launcher does).
    pub fn control_server(&self) -> Result<ControlServer, RuntimeError> {
        let service = control_service(self.node()?, self.namespace(), true)?;
        let server = service
            .server_builder()
            .create()
            .map_err(|e| RuntimeError::Port(format!("control server: {e:?}")))?;
        Ok(ControlServer { server, invalid: 0 })
    }
}

impl ControlServer {
    /// The next valid request, if one is waiting. An invalid one is answered `CONTROL_REFUSED`,
    /// counted and logged, never handed on.
    pub fn receive(&mut self) -> Option<ControlCall> {
        loop {
            let active = match self.server.receive() {
                Ok(Some(active)) => active,
                Ok(None) => return None,
                Err(e) => {
                    tracing::debug!("control receive failed: {e:?}");
                    return None;
                }
            };
            match active.payload().validate() {
                Ok(()) => return Some(ControlCall { active }),
                Err(why) => {
                    self.invalid += 1;
                    tracing::warn!("refused an invalid control request: {why}");
                    ControlCall { active }.respond(|r| {
                        r.status = CONTROL_REFUSED;
                        mole_types::write_name(&mut r.text, &format!("invalid request: {why}"));
                    });
                }
            }
        }
    }

    /// Invalid requests refused so far.
    pub fn invalid(&self) -> u64 {
        self.invalid
    }
}

impl ControlCall {
    /// The request.
    pub fn request(&self) -> &ControlRequest {
        self.active.payload()
    }

    /// Sends the one response; `fill` starts from zeros.
    pub fn respond(self, fill: impl FnOnce(&mut ControlResponse)) {
        let mut response: ControlResponse = bytemuck::Zeroable::zeroed();
        fill(&mut response);
        response.header.stamp_ns = now_ns();
        if let Err(e) = self.active.send_copy(response) {
            tracing::warn!("cannot answer a control request: {e:?}");
        }
    }
}

/// The calling end of `stack/control`, for one-shot commands.
pub struct ControlClient {
    // Field order: the client port must drop before its node.
    client: Client<ipc::Service, ControlRequest, (), ControlResponse, ()>,
    _node: Node<ipc::Service>,
}

impl ControlClient {
    /// Connects to the launcher of `namespace`; fails with a sentence when none runs.
    pub fn connect(namespace: &str) -> Result<ControlClient, RuntimeError> {
        let node = crate::admin::create_node(namespace, "control")?;
        let service = control_service(&node, namespace, false)?;
        let client = service
            .client_builder()
            .create()
            .map_err(|e| RuntimeError::Port(format!("control client: {e:?}")))?;
        Ok(ControlClient {
            client,
            _node: node,
        })
    }

    /// Sends `request` and waits up to `timeout` for the answer.
    pub fn call(
        &self,
        mut request: ControlRequest,
        timeout: Duration,
    ) -> Result<ControlResponse, RuntimeError> {
        request.header.stamp_ns = now_ns();
        let pending = self
            .client
            .send_copy(request)
            .map_err(|e| RuntimeError::Port(format!("control request: {e:?}")))?;
        let deadline = Instant::now() + timeout;
        loop {
            match pending.receive() {
                Ok(Some(response)) => {
                    let response = *response.payload();
                    return match response.validate() {
                        Ok(()) => Ok(response),
                        Err(why) => Err(RuntimeError::Port(format!(
                            "the launcher's answer is invalid: {why}"
                        ))),
                    };
                }
                Ok(None) => {}
                Err(e) => return Err(RuntimeError::Port(format!("control response: {e:?}"))),
            }
            if !pending.is_connected() {
                return Err(RuntimeError::Port(
                    "the launcher went away before answering".to_string(),
                ));
            }
            if Instant::now() >= deadline {
                return Err(RuntimeError::Port(format!(
                    "the launcher did not answer within {timeout:?}"
                )));
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}
