//! The WebSocket server (the SDK's): what it offers a client, and what comes back from one.
//!
//! A live stack offers its channels, the connection graph, its settings as parameters and the
//! time of its newest step; with its controls on, also client publishing (goals and paces,
//! [`crate::input`]) and the control services. A recording offers its channels, the time and
//! playback control (play, pause, seek, speed), answered from the playback clock. What a client
//! sends that is refused is counted, logged and never fatal.

use crate::channels::Channels;
use crate::control::{Settings, services};
use crate::graph::connection_graph;
use crate::input::client_input;
use foxglove::websocket::{
    Capability, ChannelView, Client, ClientChannel, PlaybackCommand, PlaybackControlRequest,
    PlaybackState, PlaybackStatus, ServerListener,
};
use foxglove::{Context, WebSocketServer, WebSocketServerHandle};
use mole_view::{Clock, PageInput};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::sync::{Arc, Mutex};

/// What is served.
pub enum Serving {
    /// The stack in `namespace`; goals, paces, setting changes and swaps from clients unless
    /// `controls` is off.
    Live { namespace: String, controls: bool },
    /// A recording, played by `clock` (ticks of `period_ns`).
    Recording {
        clock: Arc<Mutex<Clock>>,
        period_ns: u64,
    },
}

/// What the main loop hears from the clients.
pub struct Heard {
    /// Goals and paces, in the order they came.
    pub inputs: Receiver<PageInput>,
    /// Channels a client subscribed to since the last look (their newest sample is sent again).
    pub subscribed: Receiver<String>,
    /// Client messages refused.
    pub refused: Arc<AtomicU64>,
    /// A seek since the last look (a recording's).
    pub seeked: Arc<AtomicU64>,
}

/// A running server and its channels.
pub struct Served {
    pub handle: WebSocketServerHandle,
    /// The SDK's context of the server and the channels (both hold it weakly).
    _context: Arc<Context>,
    pub channels: Channels,
    pub heard: Heard,
    /// `ws://HOST:PORT`.
    pub url: String,
}

struct Listener {
    inputs: Sender<PageInput>,
    subscribed: Mutex<Sender<String>>,
    refused: Arc<AtomicU64>,
    seeked: Arc<AtomicU64>,
    controls: bool,
    playback: Option<(Arc<Mutex<Clock>>, u64)>,
}

impl ServerListener for Listener {
    fn on_message_data(&self, _client: Client, channel: &ClientChannel, payload: &[u8]) {
        match client_input(&channel.topic, &channel.encoding, payload, self.controls) {
            Ok(input) => {
                tracing::info!(?input, channel = channel.topic, "from a client");
                let _ = self.inputs.send(input);
            }
            Err(why) => {
                let refused = self.refused.fetch_add(1, Ordering::Relaxed) + 1;
                tracing::warn!(channel = channel.topic, %why, refused, "refused a client's message");
            }
        }
    }

    fn on_subscribe(&self, _client: Client, channel: ChannelView) {
        if let Ok(subscribed) = self.subscribed.lock() {
            let _ = subscribed.send(channel.topic().to_string());
        }
    }

    fn on_playback_control_request(
        &self,
        request: PlaybackControlRequest,
    ) -> Option<PlaybackState> {
        let (clock, period_ns) = self.playback.as_ref()?;
        let mut clock = clock.lock().ok()?;
        clock.set_speed(f64::from(request.playback_speed));
        if let Some(time) = request.seek_time {
            clock.seek(time / period_ns);
            self.seeked.fetch_add(1, Ordering::Relaxed);
        }
        match request.playback_command {
            PlaybackCommand::Play => clock.play(),
            PlaybackCommand::Pause => clock.pause(),
        }
        let mut state = playback_state(&clock, *period_ns);
        (state.did_seek, state.request_id) =
            (request.seek_time.is_some(), Some(request.request_id));
        Some(state)
    }
}

/// The playback state of `clock`.
pub fn playback_state(clock: &Clock, period_ns: u64) -> PlaybackState {
    let timeline = clock.timeline();
    let status = match (timeline.playing, timeline.tick >= timeline.last_tick) {
        (true, _) => PlaybackStatus::Playing,
        (false, true) => PlaybackStatus::Ended,
        (false, false) => PlaybackStatus::Paused,
    };
    PlaybackState {
        status,
        current_time: timeline.tick * period_ns,
        playback_speed: timeline.speed as f32,
        did_seek: false,
        request_id: None,
    }
}

/// Starts serving `serving` on `address` (port 0: any free port) and advertises every channel.
pub fn serve(address: SocketAddr, serving: Serving) -> Result<Served, Box<dyn std::error::Error>> {
    let ctx = Context::new();
    let (inputs, inputs_rx) = channel();
    let (subscribed, subscribed_rx) = channel();
    let (refused, seeked) = (Arc::new(AtomicU64::new(0)), Arc::new(AtomicU64::new(0)));
    let mut server = WebSocketServer::new()
        .name("mole")
        .bind(address.ip().to_string(), address.port())
        .context(&ctx);
    let mut capabilities = vec![Capability::Time];
    let (controls, playback) = match &serving {
        Serving::Live {
            namespace,
            controls,
        } => {
            capabilities.extend([Capability::ConnectionGraph, Capability::Parameters]);
            server = server.parameter_handler(Arc::new(Settings::new(namespace, *controls)));
            if *controls {
                capabilities.extend([Capability::ClientPublish, Capability::Services]);
                server = server
                    .services(services(namespace))
                    .supported_encodings(["json"]);
            }
            (*controls, None)
        }
        Serving::Recording { clock, period_ns } => {
            capabilities.push(Capability::PlaybackControl);
            let timeline = clock.lock().map_err(|_| "the playback clock")?.timeline();
            server = server.playback_time_range(
                timeline.first_tick * period_ns,
                timeline.last_tick * period_ns,
            );
            (false, Some((clock.clone(), *period_ns)))
        }
    };
    let listener = Listener {
        inputs,
        subscribed: Mutex::new(subscribed),
        refused: refused.clone(),
        seeked: seeked.clone(),
        controls,
        playback,
    };
    let handle = server
        .capabilities(capabilities)
        .listener(Arc::new(listener))
        .start_blocking()
        .map_err(|e| format!("cannot serve Foxglove on {address}: {e}"))?;
    if matches!(serving, Serving::Live { .. }) {
        handle.publish_connection_graph(connection_graph())?;
    }
    let channels = Channels::advertise(&ctx)?;
    let url = format!("ws://{}:{}", address.ip(), handle.port());
    Ok(Served {
        handle,
        _context: ctx,
        channels,
        heard: Heard {
            inputs: inputs_rx,
            subscribed: subscribed_rx,
            refused,
            seeked,
        },
        url,
    })
}

impl Served {
    /// Sends again the newest sample behind every channel a client subscribed to since the
    /// last call.
    pub fn resend_subscribed(&mut self) {
        while let Ok(channel) = self.heard.subscribed.try_recv() {
            self.channels.resend(&channel);
        }
    }

    /// Stops the server, saying what it did.
    pub fn finish(self) {
        let refused = self.heard.refused.load(Ordering::Relaxed);
        tracing::info!(
            logged = self.channels.logged,
            refused,
            "Foxglove server stopped"
        );
        drop(self.channels);
        self.handle.stop().wait_blocking();
    }
}
