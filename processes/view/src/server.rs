//! The page and its WebSocket: axum on a single-threaded tokio runtime in a thread of its own.
//!
//! Frames come from the main loop through a `broadcast` queue of [`FRAMES_QUEUED`]: a page that
//! keeps up is sent every frame, even when its task was not run for a few frame periods (a loaded
//! machine); one further behind skips to the newest. Each page's task keeps what it was sent
//! ([`Client`]) and sends only the tiles that changed.
//! A page's inputs go back to the main loop through a std channel; refused ones are counted
//! and logged at debug.
//!
//! Before it serves, the view binds its address ([`listen`]); once it serves, it says so to the
//! launcher ([`announce`]).

use crate::{Access, Client, Frame, MAX_INPUT_BYTES, PageInput, Rejected, admit, parse_input};
use axum::Router;
use axum::extract::State;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;
use mole_runtime::BadInput;
use std::net::{SocketAddr, TcpListener};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc;
use std::time::Instant;
use tokio::sync::broadcast;
use tokio::sync::broadcast::error::{RecvError, TryRecvError};

const INDEX_HTML: &str = include_str!("../assets/index.html");
const VIEW_JS: &str = include_str!("../assets/view.js");
const VIEW_CSS: &str = include_str!("../assets/view.css");

/// Frames a page may be behind before it skips to the newest: half a second of them.
pub const FRAMES_QUEUED: usize = 10;

/// Where the main loop sends each frame to every page.
#[derive(Clone)]
pub struct Frames(broadcast::Sender<Arc<Frame>>);

impl Frames {
    /// Sends `frame` to every page (none may be open).
    pub fn send(&self, frame: Frame) {
        let _ = self.0.send(Arc::new(frame));
    }
}

/// What every page's task shares.
#[derive(Clone)]
struct Shared {
    frames: broadcast::Sender<Arc<Frame>>,
    commands: mpsc::Sender<PageInput>,
    rejected: Arc<AtomicU64>,
    access: Access,
}

impl Shared {
    /// Takes one input: a valid command the view takes to the main loop, anything else counted.
    fn take(&self, input: Result<PageInput, Rejected>) {
        let refused = match input.and_then(|command| admit(command, self.access)) {
            Ok(command) => {
                // An error is the main loop gone: the view is ending.
                let _ = self.commands.send(command);
                return;
            }
            Err(why) => why,
        };
        self.rejected.fetch_add(1, Ordering::Relaxed);
        tracing::debug!(%refused, "a page's input was refused");
    }
}

/// The server's ends in the main loop.
pub struct Served {
    /// Where each frame goes to every page.
    pub frames: Frames,
    /// The pages' inputs that were taken.
    pub commands: mpsc::Receiver<PageInput>,
    /// Inputs refused so far.
    pub rejected: Arc<AtomicU64>,
}

impl Served {
    /// Inputs refused so far.
    #[must_use]
    pub fn rejected(&self) -> u64 {
        self.rejected.load(Ordering::Relaxed)
    }

    /// Logs the view's end: `frames` made since `started`, inputs refused.
    pub fn finished(&self, frames: u64, started: Instant) {
        tracing::info!(
            frames,
            elapsed_s = started.elapsed().as_secs_f64(),
            rejected_inputs = self.rejected(),
            "view finished"
        );
    }
}

/// The listener on `address` (in use → bad input) and the page's URL.
pub fn listen(address: SocketAddr) -> Result<(TcpListener, String), Box<dyn std::error::Error>> {
    let listener = TcpListener::bind(address)
        .map_err(|e| BadInput(format!("cannot serve the view on {address}: {e}")))?;
    let url = format!("http://{}/", listener.local_addr()?);
    Ok((listener, url))
}

/// Says the page is served: its URL into `ready_file` (`--ready-file`), for the launcher.
pub fn announce(ready_file: Option<&Path>, url: &str) -> std::io::Result<()> {
    if let Some(file) = ready_file {
        std::fs::write(file, url)?;
    }
    Ok(())
}

/// Serves the page on `listener` (bound already, so a port in use is the caller's error) from
/// a thread of its own; the pages' inputs that `access` takes go to [`Served::commands`].
pub fn serve(listener: TcpListener, access: Access) -> std::io::Result<Served> {
    listener.set_nonblocking(true)?;
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let (frames, _) = broadcast::channel(FRAMES_QUEUED);
    let (commands_in, commands) = mpsc::channel();
    let rejected = Arc::new(AtomicU64::new(0));
    let shared = Shared {
        frames: frames.clone(),
        commands: commands_in,
        rejected: rejected.clone(),
        access,
    };
    let app = Router::new()
        .route("/", get(|| async { Html(INDEX_HTML) }))
        .route(
            "/view.js",
            get(|| async { asset("text/javascript", VIEW_JS) }),
        )
        .route("/view.css", get(|| async { asset("text/css", VIEW_CSS) }))
        .route("/ws", get(upgrade))
        .with_state(shared);
    std::thread::Builder::new()
        .name("server".into())
        .spawn(move || {
            runtime.block_on(async move {
                let listener = tokio::net::TcpListener::from_std(listener)?;
                axum::serve(listener, app).await
            })
        })?;
    Ok(Served {
        frames: Frames(frames),
        commands,
        rejected,
    })
}

fn asset(content_type: &'static str, body: &'static str) -> Response {
    ([(header::CONTENT_TYPE, content_type)], body).into_response()
}

/// Whether a browser's WebSocket comes from the view's own page: another site open in the same
/// browser could otherwise steer the robot through it. Clients that send no `Origin` (not a
/// browser) are let in.
fn same_origin(headers: &HeaderMap) -> bool {
    let Some(origin) = headers.get(header::ORIGIN) else {
        return true;
    };
    let host = headers.get(header::HOST).and_then(|h| h.to_str().ok());
    let origin_host = origin
        .to_str()
        .ok()
        .and_then(|o| o.split_once("://"))
        .map(|(_, authority)| authority);
    host.is_some() && origin_host == host
}

async fn upgrade(
    State(shared): State<Shared>,
    headers: HeaderMap,
    ws: WebSocketUpgrade,
) -> Response {
    if !same_origin(&headers) {
        tracing::warn!(origin = ?headers.get(header::ORIGIN), "a WebSocket from another site was refused");
        return StatusCode::FORBIDDEN.into_response();
    }
    ws.max_message_size(MAX_INPUT_BYTES)
        .max_frame_size(MAX_INPUT_BYTES)
        .on_upgrade(move |socket| page(socket, shared))
}

/// Whether a receive error is the size cap (the one error a page's input can cause; the others
/// are a connection that broke).
fn too_long(error: &axum::Error) -> bool {
    let mut source: Option<&dyn std::error::Error> = Some(error);
    while let Some(e) = source {
        let text = e.to_string();
        if text.contains("Space limit exceeded") || text.contains("too long") {
            return true;
        }
        source = e.source();
    }
    false
}

/// The newest frame queued for a page that fell behind (`None`: none queued any more).
fn newest(frames: &mut broadcast::Receiver<Arc<Frame>>) -> Option<Arc<Frame>> {
    let mut newest = None;
    loop {
        match frames.try_recv() {
            Ok(frame) => newest = Some(frame),
            Err(TryRecvError::Lagged(_)) => {}
            Err(TryRecvError::Empty | TryRecvError::Closed) => return newest,
        }
    }
}

/// One page: every frame made from its connection on out (as what changed for it; the newest
/// only once it fell [`FRAMES_QUEUED`] behind), its inputs in, until it leaves or the view ends.
async fn page(mut socket: WebSocket, shared: Shared) {
    let mut frames = shared.frames.subscribe();
    let mut client = Client::default();
    loop {
        tokio::select! {
            received = frames.recv() => {
                let frame = match received {
                    Ok(frame) => frame,
                    Err(RecvError::Lagged(skipped)) => {
                        tracing::debug!(skipped, "a page fell behind: it skips to the newest frame");
                        let Some(frame) = newest(&mut frames) else {
                            continue;
                        };
                        frame
                    }
                    Err(RecvError::Closed) => break,
                };
                let text = client.message(&frame);
                if socket.send(Message::Text(text.into())).await.is_err() {
                    break;
                }
            }
            incoming = socket.recv() => match incoming {
                None | Some(Ok(Message::Close(_))) => break,
                Some(Ok(Message::Text(text))) => shared.take(parse_input(text.as_str())),
                Some(Ok(Message::Binary(_))) => shared.take(Err(Rejected::Binary)),
                Some(Ok(Message::Ping(_) | Message::Pong(_))) => {}
                Some(Err(e)) => {
                    if too_long(&e) {
                        shared.take(Err(Rejected::Oversized));
                    } else {
                        tracing::debug!("a page's connection broke: {e}");
                    }
                    break;
                }
            },
        }
    }
}
