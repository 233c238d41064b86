//! One endpoint's ports on one transport behind one trait, so every measurement loop runs the
//! same code over the runtime, raw iceoryx2, a Unix socket and TCP.

use crate::messages::{BenchAck, BenchMessage, HEADER_BYTES};
use crate::{BenchError, WakeMode};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use mole_runtime::{ClockMode, CommonArgs, Context, Wake, Waker, now_ns};
use mole_types::{Message, Topic};
use std::io::{Read, Write};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// Sequence number that ends a run: the probe acknowledges (throughput), forwards (chain) and
/// exits.
pub(crate) const STOP: u64 = u64::MAX;
/// Sequence numbers from here on are hand-shake rounds, never measured.
pub(crate) const WARMUP: u64 = 1 << 62;

/// What the sender measured around one send.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct SendTimes {
    /// Loan of the sample (0 for sockets, which have none).
    pub loan_ns: u64,
    /// Writing the payload bytes (0 when not asked to).
    pub fill_ns: u64,
}

/// One received message, stamped on receipt.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Received {
    /// The sender's sequence number (the header's `tick`).
    pub seq: u64,
    /// The header's `stamp_ns`: stamped after the payload was written, right before the send.
    pub send_ns: u64,
    /// The header's `origin_ns`: the first sender's time before its loan (chains forward it).
    pub origin_ns: u64,
    /// `now_ns()` on receipt.
    pub recv_ns: u64,
}

/// An endpoint: some of a data output, a data input, an ack output and an ack input.
pub(crate) trait Link {
    /// Loans, optionally fills the payload, stamps and sends one data message.
    fn send(
        &mut self,
        seq: u64,
        origin_ns: Option<u64>,
        fill: bool,
    ) -> Result<SendTimes, BenchError>;
    /// Hands every queued data message to `on`; waits (per wake mode) until at least one came
    /// or `deadline` passed. Returns how many.
    fn recv(
        &mut self,
        deadline: Instant,
        on: &mut dyn FnMut(Received),
    ) -> Result<usize, BenchError>;
    /// Sends an acknowledgement.
    fn send_ack(&mut self, ack: &BenchAck) -> Result<(), BenchError>;
    /// As [`Link::recv`], for acknowledgements.
    fn recv_ack(
        &mut self,
        deadline: Instant,
        on: &mut dyn FnMut(&BenchAck),
    ) -> Result<usize, BenchError>;
}

/// A service's name below the namespace and the capacities both sides must agree on.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PortSpec {
    pub name: &'static str,
    pub buffer: usize,
    pub max_publishers: usize,
    pub max_subscribers: usize,
}

/// Which ports an endpoint opens.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Ports {
    pub data_out: Option<PortSpec>,
    pub data_in: Option<PortSpec>,
    pub ack_out: Option<PortSpec>,
    pub ack_in: Option<PortSpec>,
}

fn missing(port: &str) -> BenchError {
    BenchError::Internal(format!("this endpoint has no {port} port"))
}

fn iox(what: &str, e: impl core::fmt::Debug) -> BenchError {
    BenchError::Iceoryx(format!("{what}: {e:?}"))
}

// ---------------------------------------------------------------------------------------------
// The runtime: the code path the stack uses.
// ---------------------------------------------------------------------------------------------

fn topic<M>(spec: PortSpec) -> Topic<M> {
    Topic::new(spec.name)
        .buffer(spec.buffer)
        .max_publishers(spec.max_publishers)
        .max_subscribers(spec.max_subscribers)
}

struct RuntimeLink<'a, M: BenchMessage> {
    ctx: &'a mut Context,
    waitset: &'a mole_runtime::WaitSet,
    wake: WakeMode,
    data_out: Option<mole_runtime::Publisher<M>>,
    data_in: Option<mole_runtime::Subscriber<M>>,
    ack_out: Option<mole_runtime::Publisher<BenchAck>>,
    ack_in: Option<mole_runtime::Subscriber<BenchAck>>,
}

/// Opens `ports` through mole-runtime (realtime mode, node `mole/<namespace>/<role>`) and runs
/// `f` on the endpoint; everything is dropped cleanly afterwards.
pub(crate) fn with_runtime<M: BenchMessage, T>(
    namespace: &str,
    role: &str,
    ports: &Ports,
    wake: WakeMode,
    f: impl FnOnce(&mut dyn Link) -> Result<T, BenchError>,
) -> Result<T, BenchError> {
    let args = CommonArgs::attach(namespace, ClockMode::Realtime);
    let mut ctx = Context::with_shutdown_flag(role, &args, Arc::new(AtomicBool::new(false)))?;
    let data_out = ports
        .data_out
        .map(|p| ctx.publisher(topic::<M>(p)))
        .transpose()?;
    let data_in = ports
        .data_in
        .map(|p| ctx.subscriber(topic::<M>(p)))
        .transpose()?;
    let ack_out = ports
        .ack_out
        .map(|p| ctx.publisher(topic::<BenchAck>(p)))
        .transpose()?;
    let ack_in = ports
        .ack_in
        .map(|p| ctx.subscriber(topic::<BenchAck>(p)))
        .transpose()?;
    let waitset = ctx.waitset()?;
    let wakers: Vec<Waker> = data_in
        .iter()
        .map(|s| s.waker())
        .chain(ack_in.iter().map(|s| s.waker()))
        .collect();
    let mut attachments = Vec::with_capacity(wakers.len());
    for waker in &wakers {
        attachments.push(waitset.attach(waker)?);
    }
    let mut link = RuntimeLink {
        ctx: &mut ctx,
        waitset: &waitset,
        wake,
        data_out,
        data_in,
        ack_out,
        ack_in,
    };
    let result = f(&mut link);
    drop(link);
    drop(attachments);
    result
}

impl<M: BenchMessage> RuntimeLink<'_, M> {
    /// Waits for the next chance of data; `false` once the deadline passed.
    fn wait(&mut self, deadline: Instant) -> Result<bool, BenchError> {
        match self.wake {
            WakeMode::Busy | WakeMode::Blocking => {
                core::hint::spin_loop();
                Ok(Instant::now() < deadline)
            }
            WakeMode::Event => match self.waitset.wait(self.ctx, Some(deadline))? {
                Wake::Data => Ok(true),
                Wake::Timeout | Wake::Shutdown => Ok(false),
            },
        }
    }
}

impl<M: BenchMessage> Link for RuntimeLink<'_, M> {
    fn send(
        &mut self,
        seq: u64,
        origin_ns: Option<u64>,
        fill: bool,
    ) -> Result<SendTimes, BenchError> {
        let publisher = self.data_out.as_mut().ok_or_else(|| missing("data out"))?;
        let t0 = now_ns();
        let (mut fill_start, mut fill_end) = (t0, t0);
        // The runtime stamps `stamp_ns` after `fill` returns, right before the send.
        publisher.publish(seq, origin_ns.unwrap_or(t0), |m: &mut M| {
            fill_start = now_ns();
            if fill {
                m.payload_mut().fill(seq as u8);
            }
            fill_end = now_ns();
        })?;
        Ok(SendTimes {
            loan_ns: fill_start.saturating_sub(t0),
            fill_ns: fill_end.saturating_sub(fill_start),
        })
    }

    fn recv(
        &mut self,
        deadline: Instant,
        on: &mut dyn FnMut(Received),
    ) -> Result<usize, BenchError> {
        loop {
            let subscriber = self.data_in.as_mut().ok_or_else(|| missing("data in"))?;
            let n = subscriber.drain(|m| {
                let recv_ns = now_ns();
                let h = m.header();
                on(Received {
                    seq: h.tick,
                    send_ns: h.stamp_ns,
                    origin_ns: h.origin_ns,
                    recv_ns,
                });
            });
            if n > 0 {
                return Ok(n);
            }
            if !self.wait(deadline)? {
                return Ok(0);
            }
        }
    }

    fn send_ack(&mut self, ack: &BenchAck) -> Result<(), BenchError> {
        let publisher = self.ack_out.as_mut().ok_or_else(|| missing("ack out"))?;
        publisher.publish(ack.seq, 0, |m| ack.copy_body_into(m))?;
        Ok(())
    }

    fn recv_ack(
        &mut self,
        deadline: Instant,
        on: &mut dyn FnMut(&BenchAck),
    ) -> Result<usize, BenchError> {
        loop {
            let subscriber = self.ack_in.as_mut().ok_or_else(|| missing("ack in"))?;
            let n = subscriber.drain(|a| on(a));
            if n > 0 {
                return Ok(n);
            }
            if !self.wait(deadline)? {
                return Ok(0);
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Raw iceoryx2: publish-subscribe plus an event service, as the runtime uses underneath, without
// its validation, statistics and header stamping.
// ---------------------------------------------------------------------------------------------

struct RawOut<M: Message + 'static> {
    publisher: iceoryx2::port::publisher::Publisher<ipc::Service, M, ()>,
    notifier: Notifier<ipc::Service>,
}

struct RawIn<M: Message + 'static> {
    subscriber: iceoryx2::port::subscriber::Subscriber<ipc::Service, M, ()>,
    listener: Listener<ipc::Service>,
}

type PubSubFactory<M> =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, M, ()>;
type EventFactory = iceoryx2::service::port_factory::event::PortFactory<ipc::Service>;

fn raw_services<M: Message + 'static>(
    node: &Node<ipc::Service>,
    namespace: &str,
    spec: PortSpec,
) -> Result<(PubSubFactory<M>, EventFactory), BenchError> {
    let full = mole_types::topics::service_name(namespace, spec.name);
    let name: ServiceName = full
        .as_str()
        .try_into()
        .map_err(|e| iox(&format!("service name `{full}`"), e))?;
    let pubsub = node
        .service_builder(&name)
        .publish_subscribe::<M>()
        .history_size(0)
        .subscriber_max_buffer_size(spec.buffer)
        .subscriber_max_borrowed_samples(2)
        .max_publishers(spec.max_publishers)
        .max_subscribers(spec.max_subscribers)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| iox(&format!("open `{full}`"), e))?;
    let event = node
        .service_builder(&name)
        .event()
        .max_notifiers(spec.max_publishers + 2)
        .max_listeners(spec.max_subscribers + 2)
        .open_or_create()
        .map_err(|e| iox(&format!("open the event of `{full}`"), e))?;
    Ok((pubsub, event))
}

fn raw_out<M: Message + 'static>(
    node: &Node<ipc::Service>,
    namespace: &str,
    spec: PortSpec,
) -> Result<RawOut<M>, BenchError> {
    let (pubsub, event) = raw_services::<M>(node, namespace, spec)?;
    Ok(RawOut {
        publisher: pubsub
            .publisher_builder()
            .max_loaned_samples(2)
            .create()
            .map_err(|e| iox("publisher", e))?,
        notifier: event
            .notifier_builder()
            .create()
            .map_err(|e| iox("notifier", e))?,
    })
}

fn raw_in<M: Message + 'static>(
    node: &Node<ipc::Service>,
    namespace: &str,
    spec: PortSpec,
) -> Result<RawIn<M>, BenchError> {
    let (pubsub, event) = raw_services::<M>(node, namespace, spec)?;
    Ok(RawIn {
        subscriber: pubsub
            .subscriber_builder()
            .buffer_size(spec.buffer)
            .create()
            .map_err(|e| iox("subscriber", e))?,
        listener: event
            .listener_builder()
            .create()
            .map_err(|e| iox("listener", e))?,
    })
}

impl<M: Message + 'static> RawOut<M> {
    /// Loan → write → stamp → send (→ notify in event mode).
    fn send(
        &self,
        wake: WakeMode,
        write: impl FnOnce(&mut M) -> (u64, u64),
    ) -> Result<SendTimes, BenchError> {
        let t0 = now_ns();
        let sample = self.publisher.loan_uninit().map_err(|e| iox("loan", e))?;
        // SAFETY: the sample lives in a shared-memory segment that the OS zero-filled when it
        // was mapped and that only ever holds whole messages afterwards, so every byte is
        // initialised; `M: Pod` makes any byte pattern a valid `M` (as in mole-runtime).
        let mut sample = unsafe { sample.assume_init() };
        let (fill_start, fill_end) = write(sample.payload_mut());
        sample.payload_mut().header_mut().stamp_ns = now_ns();
        sample.send().map_err(|e| iox("send", e))?;
        if wake == WakeMode::Event {
            self.notifier.notify().map_err(|e| iox("notify", e))?;
        }
        Ok(SendTimes {
            loan_ns: fill_start.saturating_sub(t0),
            fill_ns: fill_end.saturating_sub(fill_start),
        })
    }
}

impl<M: Message + 'static> RawIn<M> {
    /// Receives every queued sample (clearing the wake-up signals first in event mode).
    fn drain(&self, wake: WakeMode, mut on: impl FnMut(&M)) -> Result<usize, BenchError> {
        if wake == WakeMode::Event {
            self.listener
                .try_wait(|_| {})
                .map_err(|e| iox("listener", e))?;
        }
        let mut n = 0;
        while let Some(sample) = self.subscriber.receive().map_err(|e| iox("receive", e))? {
            on(sample.payload());
            n += 1;
        }
        Ok(n)
    }
}

struct RawLink<'a, M: BenchMessage + 'static> {
    waitset: &'a iceoryx2::waitset::WaitSet<ipc::Service>,
    wake: WakeMode,
    data_out: Option<&'a RawOut<M>>,
    data_in: Option<&'a RawIn<M>>,
    ack_out: Option<&'a RawOut<BenchAck>>,
    ack_in: Option<&'a RawIn<BenchAck>>,
}

/// Opens `ports` with raw iceoryx2 (node `mole/<namespace>/<role>`, same service settings as
/// the runtime) and runs `f` on the endpoint.
pub(crate) fn with_raw<M: BenchMessage + 'static, T>(
    namespace: &str,
    role: &str,
    ports: &Ports,
    wake: WakeMode,
    f: impl FnOnce(&mut dyn Link) -> Result<T, BenchError>,
) -> Result<T, BenchError> {
    let node_name = format!("mole/{namespace}/{role}");
    let name: NodeName = node_name
        .as_str()
        .try_into()
        .map_err(|e| iox(&format!("node name `{node_name}`"), e))?;
    let node = NodeBuilder::new()
        .name(&name)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| iox(&format!("node `{node_name}`"), e))?;
    let data_out = ports
        .data_out
        .map(|p| raw_out::<M>(&node, namespace, p))
        .transpose()?;
    let data_in = ports
        .data_in
        .map(|p| raw_in::<M>(&node, namespace, p))
        .transpose()?;
    let ack_out = ports
        .ack_out
        .map(|p| raw_out::<BenchAck>(&node, namespace, p))
        .transpose()?;
    let ack_in = ports
        .ack_in
        .map(|p| raw_in::<BenchAck>(&node, namespace, p))
        .transpose()?;
    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<ipc::Service>()
        .map_err(|e| iox("waitset", e))?;
    let mut guards = Vec::with_capacity(2);
    if let Some(input) = &data_in {
        guards.push(
            waitset
                .attach_notification(&input.listener)
                .map_err(|e| iox("attach", e))?,
        );
    }
    if let Some(input) = &ack_in {
        guards.push(
            waitset
                .attach_notification(&input.listener)
                .map_err(|e| iox("attach", e))?,
        );
    }
    let mut link = RawLink {
        waitset: &waitset,
        wake,
        data_out: data_out.as_ref(),
        data_in: data_in.as_ref(),
        ack_out: ack_out.as_ref(),
        ack_in: ack_in.as_ref(),
    };
    let result = f(&mut link);
    drop(guards);
    result
}

impl<M: BenchMessage + 'static> RawLink<'_, M> {
    fn wait(&self, deadline: Instant) -> Result<bool, BenchError> {
        match self.wake {
            WakeMode::Busy | WakeMode::Blocking => {
                core::hint::spin_loop();
                Ok(Instant::now() < deadline)
            }
            WakeMode::Event => {
                let left = deadline.saturating_duration_since(Instant::now());
                if left == Duration::ZERO {
                    return Ok(false);
                }
                self.waitset
                    .wait_and_process_once_with_timeout(|_| CallbackProgression::Continue, left)
                    .map_err(|e| iox("wait", e))?;
                Ok(Instant::now() < deadline)
            }
        }
    }
}

impl<M: BenchMessage + 'static> Link for RawLink<'_, M> {
    fn send(
        &mut self,
        seq: u64,
        origin_ns: Option<u64>,
        fill: bool,
    ) -> Result<SendTimes, BenchError> {
        let out = self.data_out.ok_or_else(|| missing("data out"))?;
        let t0 = now_ns();
        out.send(self.wake, |m| {
            let fill_start = now_ns();
            if fill {
                m.payload_mut().fill(seq as u8);
            }
            let fill_end = now_ns();
            let h = m.header_mut();
            h.seq = seq;
            h.tick = seq;
            h.origin_ns = origin_ns.unwrap_or(t0);
            (fill_start, fill_end)
        })
    }

    fn recv(
        &mut self,
        deadline: Instant,
        on: &mut dyn FnMut(Received),
    ) -> Result<usize, BenchError> {
        let input = self.data_in.ok_or_else(|| missing("data in"))?;
        loop {
            let n = input.drain(self.wake, |m| {
                let recv_ns = now_ns();
                let h = m.header();
                on(Received {
                    seq: h.tick,
                    send_ns: h.stamp_ns,
                    origin_ns: h.origin_ns,
                    recv_ns,
                });
            })?;
            if n > 0 {
                return Ok(n);
            }
            if !self.wait(deadline)? {
                return Ok(0);
            }
        }
    }

    fn send_ack(&mut self, ack: &BenchAck) -> Result<(), BenchError> {
        let out = self.ack_out.ok_or_else(|| missing("ack out"))?;
        let wake = self.wake;
        out.send(wake, |m| {
            ack.copy_body_into(m);
            m.header.tick = ack.seq;
            (0, 0)
        })?;
        Ok(())
    }

    fn recv_ack(
        &mut self,
        deadline: Instant,
        on: &mut dyn FnMut(&BenchAck),
    ) -> Result<usize, BenchError> {
        let input = self.ack_in.ok_or_else(|| missing("ack in"))?;
        loop {
            let n = input.drain(self.wake, |a| on(a))?;
            if n > 0 {
                return Ok(n);
            }
            if !self.wait(deadline)? {
                return Ok(0);
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Sockets: fixed-size frames (the message's bytes) one way, 80-byte acks the other.
// ---------------------------------------------------------------------------------------------

/// A connected stream socket (Unix or TCP) carrying `size`-byte frames with the header's layout
/// in the first 32 bytes; reads block (with a timeout), so the wake mode is always blocking.
pub(crate) struct StreamLink<S: Read + Write> {
    stream: S,
    frame: Vec<u8>,
}

impl<S: Read + Write> StreamLink<S> {
    /// A link over `stream` for frames of `size` bytes (at least the header).
    pub fn new(stream: S, size: usize) -> Self {
        StreamLink {
            stream,
            frame: vec![0; size.max(HEADER_BYTES)],
        }
    }
}

fn io_error(what: &'static str) -> impl FnOnce(std::io::Error) -> BenchError {
    move |e| match e.kind() {
        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut => {
            BenchError::Timeout(format!("{what}: the peer did not answer"))
        }
        _ => BenchError::Io { what, source: e },
    }
}

fn put_u64(bytes: &mut [u8], offset: usize, value: u64) {
    bytes[offset..offset + 8].copy_from_slice(&value.to_ne_bytes());
}

fn get_u64(bytes: &[u8], offset: usize) -> u64 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&bytes[offset..offset + 8]);
    u64::from_ne_bytes(b)
}

// Offsets of the header's fields (mole_types::Header is four u64 in this order).
const SEQ: usize = 0;
const TICK: usize = 8;
const STAMP: usize = 16;
const ORIGIN: usize = 24;

impl<S: Read + Write> Link for StreamLink<S> {
    fn send(
        &mut self,
        seq: u64,
        origin_ns: Option<u64>,
        fill: bool,
    ) -> Result<SendTimes, BenchError> {
        let t0 = now_ns();
        if fill {
            self.frame[HEADER_BYTES..].fill(seq as u8);
        }
        let fill_end = now_ns();
        put_u64(&mut self.frame, SEQ, seq);
        put_u64(&mut self.frame, TICK, seq);
        put_u64(&mut self.frame, ORIGIN, origin_ns.unwrap_or(t0));
        put_u64(&mut self.frame, STAMP, now_ns());
        self.stream
            .write_all(&self.frame)
            .map_err(io_error("socket send"))?;
        Ok(SendTimes {
            loan_ns: 0,
            fill_ns: fill_end.saturating_sub(t0),
        })
    }

    fn recv(
        &mut self,
        _deadline: Instant,
        on: &mut dyn FnMut(Received),
    ) -> Result<usize, BenchError> {
        self.stream
            .read_exact(&mut self.frame)
            .map_err(io_error("socket receive"))?;
        let recv_ns = now_ns();
        on(Received {
            seq: get_u64(&self.frame, TICK),
            send_ns: get_u64(&self.frame, STAMP),
            origin_ns: get_u64(&self.frame, ORIGIN),
            recv_ns,
        });
        Ok(1)
    }

    fn send_ack(&mut self, ack: &BenchAck) -> Result<(), BenchError> {
        self.stream
            .write_all(bytemuck::bytes_of(ack))
            .map_err(io_error("socket ack send"))
    }

    fn recv_ack(
        &mut self,
        _deadline: Instant,
        on: &mut dyn FnMut(&BenchAck),
    ) -> Result<usize, BenchError> {
        let mut bytes = [0u8; core::mem::size_of::<BenchAck>()];
        self.stream
            .read_exact(&mut bytes)
            .map_err(io_error("socket ack receive"))?;
        let ack: BenchAck = bytemuck::pod_read_unaligned(&bytes);
        on(&ack);
        Ok(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::net::UnixStream;

    #[test]
    fn stream_frames_carry_the_header_and_acks_round_trip() {
        let (a, b) = UnixStream::pair().expect("socket pair");
        let mut tx = StreamLink::new(a, 1024);
        let mut rx = StreamLink::new(b, 1024);
        let times = tx.send(42, Some(7), true).expect("send");
        assert_eq!(times.loan_ns, 0);
        let mut got = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(1);
        assert_eq!(rx.recv(deadline, &mut |r| got.push(r)).expect("recv"), 1);
        assert_eq!(got[0].seq, 42);
        assert_eq!(got[0].origin_ns, 7);
        assert!(got[0].send_ns <= got[0].recv_ns);
        assert!(rx.frame[HEADER_BYTES..].iter().all(|&b| b == 42));
        let ack = BenchAck {
            seq: 42,
            send_ns: 1,
            recv_ns: 2,
            probe: 3,
            ..BenchAck::default()
        };
        rx.send_ack(&ack).expect("ack");
        let mut acks = Vec::new();
        tx.recv_ack(deadline, &mut |a| acks.push(*a))
            .expect("recv ack");
        assert_eq!(acks, vec![ack]);
    }

    #[test]
    fn a_closed_peer_is_an_error_not_a_hang() {
        let (a, b) = UnixStream::pair().expect("socket pair");
        drop(a);
        let mut rx = StreamLink::new(b, 64);
        let deadline = Instant::now() + Duration::from_secs(1);
        assert!(rx.recv(deadline, &mut |_| {}).is_err());
    }
}
