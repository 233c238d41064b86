//! The channels a stack is served on: every channel of the mapping `mole export --foxglove`
//! writes (Foxglove's well-known schemas as JSON, [`mole_recorder::foxglove::CHANNELS`]), every
//! topic's raw layout (`/mole/<topic>`, the recording's own schema and bytes) and the events
//! (`/mole/stack/events`).
//!
//! A sample is converted only when a client subscribed to a channel it becomes, and written only
//! to subscribed channels: with no client connected, serving costs the stack a drain of its
//! queues and nothing more. The newest sample of each topic is kept, so a client that subscribes
//! late still gets the world's map (published once) and the grids ([`Channels::resend`]).

use foxglove::{ChannelBuilder, Context, FoxgloveError, PartialMetadata, RawChannel, Schema};
use mole_recorder::events::{EVENT_SCHEMA, EVENT_SCHEMA_NAME, EVENTS_TOPIC};
use mole_recorder::foxglove::{
    CHANNELS, Channel, Converter, JSON_MESSAGE_ENCODING, JSON_SCHEMA_ENCODING, schemas,
};
use mole_recorder::{MESSAGE_ENCODING, SCHEMA_ENCODING, schema_json};
use mole_types::topics;
use std::collections::BTreeMap;
use std::sync::Arc;

/// The Foxglove channel of a mole topic's raw layout.
pub fn raw_channel(topic: &str) -> String {
    format!("/mole/{topic}")
}

/// Every channel, advertised once at the start.
pub struct Channels {
    /// Per mole topic, its raw layout.
    raw: Vec<(&'static str, Arc<RawChannel>)>,
    /// The mapping's channels, in [`CHANNELS`]'s order.
    converted: Vec<(Channel, Arc<RawChannel>)>,
    events: Arc<RawChannel>,
    converter: Converter,
    /// The newest sample of each topic and its log time (buffers reused from sample to sample).
    newest: BTreeMap<&'static str, (u64, Vec<u8>)>,
    /// Messages written to subscribed channels.
    pub logged: u64,
}

impl Channels {
    /// Advertises every channel in `ctx` (the server's).
    pub fn advertise(ctx: &Arc<Context>) -> Result<Channels, FoxgloveError> {
        let build = |name: String, encoding: &str, schema: Schema| {
            ChannelBuilder::new(name)
                .message_encoding(encoding)
                .schema(schema)
                .context(ctx)
                .build_raw()
        };
        let mut raw = Vec::new();
        for (topic, type_name) in topics::all() {
            let layout = schema_json(type_name).expect("every topic's type is in the layout table");
            let schema = Schema::new(type_name, SCHEMA_ENCODING, layout.into_bytes());
            raw.push((topic, build(raw_channel(topic), MESSAGE_ENCODING, schema)?));
        }
        let mut converted = Vec::new();
        for channel in CHANNELS {
            let text = schemas::json_schema(channel.schema).expect("the table's schemas exist");
            let schema = Schema::new(channel.schema, JSON_SCHEMA_ENCODING, text.as_bytes());
            let name = channel.channel.to_string();
            converted.push((channel, build(name, JSON_MESSAGE_ENCODING, schema)?));
        }
        let schema = Schema::new(
            EVENT_SCHEMA_NAME,
            JSON_SCHEMA_ENCODING,
            EVENT_SCHEMA.as_bytes(),
        );
        let events = build(raw_channel(EVENTS_TOPIC), JSON_MESSAGE_ENCODING, schema)?;
        Ok(Channels {
            raw,
            converted,
            events,
            converter: Converter::default(),
            newest: BTreeMap::new(),
            logged: 0,
        })
    }

    /// Writes the sample `data` of `topic`, of the simulated time `log_time` (ns), to its raw
    /// channel and converted to the mapping's channels, each only if a client subscribed.
    pub fn log(&mut self, topic: &str, log_time: u64, data: &[u8]) {
        if let Some((topic, _)) = self.raw.iter().find(|(t, _)| *t == topic) {
            let (time, newest) = self.newest.entry(topic).or_default();
            *time = log_time;
            newest.clear();
            newest.extend_from_slice(data);
        }
        self.write(topic, log_time, data);
    }

    /// Writes the newest sample of the topic `channel` (a Foxglove channel's name) is made
    /// from again: for a client that just subscribed to it.
    pub fn resend(&mut self, channel: &str) {
        let source = self
            .raw
            .iter()
            .find(|(_, c)| c.topic() == channel)
            .map(|(t, _)| *t)
            .or_else(|| {
                CHANNELS
                    .iter()
                    .find(|c| c.channel == channel)
                    .map(|c| c.source)
            });
        let Some(topic) = source else {
            return;
        };
        let Some((time, data)) = self.newest.remove(topic) else {
            return;
        };
        self.converter.forget_grids();
        self.write(topic, time, &data);
        self.newest.insert(topic, (time, data));
    }

    fn write(&mut self, topic: &str, log_time: u64, data: &[u8]) {
        let meta = || PartialMetadata {
            log_time: Some(log_time),
        };
        if let Some((_, raw)) = self.raw.iter().find(|(t, _)| *t == topic)
            && raw.has_sinks()
        {
            raw.log_with_meta(data, meta());
            self.logged += 1;
        }
        let wanted =
            |(c, channel): &(Channel, Arc<RawChannel>)| c.source == topic && channel.has_sinks();
        if !self.converted.iter().any(wanted) {
            return;
        }
        for message in self.converter.convert(topic, log_time, data) {
            let Some((_, channel)) = self
                .converted
                .iter()
                .find(|(c, _)| c.channel == message.topic)
            else {
                continue;
            };
            if channel.has_sinks() {
                channel.log_with_meta(message.message.to_string().as_bytes(), meta());
                self.logged += 1;
            }
        }
    }

    /// Writes an event (the recorder's JSON) at `log_time`, if a client subscribed.
    pub fn log_event(&mut self, log_time: u64, json: &str) {
        if self.events.has_sinks() {
            self.events.log_with_meta(
                json.as_bytes(),
                PartialMetadata {
                    log_time: Some(log_time),
                },
            );
            self.logged += 1;
        }
    }

    /// The names of every channel, as a client lists them.
    pub fn names(&self) -> Vec<String> {
        let raw = self.raw.iter().map(|(_, c)| c.topic().to_string());
        let converted = self.converted.iter().map(|(c, _)| c.channel.to_string());
        raw.chain(converted)
            .chain([self.events.topic().to_string()])
            .collect()
    }
}

impl Drop for Channels {
    /// Unadvertises every channel.
    fn drop(&mut self) {
        for (_, channel) in &self.raw {
            channel.close();
        }
        for (_, channel) in &self.converted {
            channel.close();
        }
        self.events.close();
    }
}
