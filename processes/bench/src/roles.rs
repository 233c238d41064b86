//! The measurement loops, written once over [`Link`]: the driver's side (latency, throughput,
//! fan-out, chain) and the probes' side (echo, sink, hop).

use crate::BenchError;
use crate::floor::next_slot;
use crate::link::{Link, Received, STOP, WARMUP};
use crate::messages::BenchAck;
use std::time::{Duration, Instant};

/// How long one hand-shake round waits for the probes' answers before asking again.
const ROUND: Duration = Duration::from_millis(20);

/// Raw samples of one latency point (ns), one entry per measured message.
#[derive(Debug, Default)]
pub(crate) struct LatencySamples {
    /// send → receive (the last subscriber's receipt for fan-out).
    pub latency: Vec<u64>,
    /// loan → send → receive.
    pub handoff: Vec<u64>,
    /// Writing the payload.
    pub fill: Vec<u64>,
}

/// What a throughput run measured.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ThroughputSamples {
    /// Messages the driver sent.
    pub sent: u64,
    /// How long the driver sent (s).
    pub send_secs: f64,
    /// The sink's totals.
    pub totals: BenchAck,
}

fn all_probes(probes: usize) -> u64 {
    if probes >= 64 {
        u64::MAX
    } else {
        (1u64 << probes) - 1
    }
}

fn probe_bit(probe: u32) -> u64 {
    1u64.checked_shl(probe).unwrap_or(0)
}

/// Sends hand-shake rounds until every probe acknowledged the same round: then every port is
/// connected both ways.
pub(crate) fn handshake(
    link: &mut dyn Link,
    probes: usize,
    deadline: Instant,
) -> Result<(), BenchError> {
    let all = all_probes(probes);
    for round in 0u64.. {
        let seq = WARMUP + round;
        link.send(seq, None, false)?;
        let mut seen = 0u64;
        let round_end = Instant::now() + ROUND;
        while Instant::now() < round_end && seen != all {
            link.recv_ack(round_end, &mut |a| {
                if a.seq == seq {
                    seen |= probe_bit(a.probe);
                }
            })?;
        }
        if seen == all {
            return Ok(());
        }
        if Instant::now() >= deadline {
            break;
        }
    }
    Err(BenchError::Startup(format!(
        "{probes} probe(s) did not all answer in time"
    )))
}

/// Ping-pong: sends `warm + samples` messages one at a time (payload written each time), each
/// after every probe acknowledged the previous one (`period` None: flat out) or, paced, on the
/// next slot of `period` after that; keeps the last `samples`.
pub(crate) fn drive_latency(
    link: &mut dyn Link,
    probes: usize,
    warm: usize,
    samples: usize,
    period: Option<Duration>,
    timeout: Duration,
) -> Result<LatencySamples, BenchError> {
    let all = all_probes(probes);
    let mut out = LatencySamples {
        latency: Vec::with_capacity(samples),
        handoff: Vec::with_capacity(samples),
        fill: Vec::with_capacity(samples),
    };
    let start = Instant::now();
    for k in 0..(warm + samples) as u64 {
        if let Some(period) = period {
            let now = Instant::now();
            std::thread::sleep(next_slot(start, period, now) - now);
        }
        let times = link.send(k, None, true)?;
        let deadline = Instant::now() + timeout;
        let (mut seen, mut send_ns, mut last_recv_ns) = (0u64, 0u64, 0u64);
        while seen != all {
            let n = link.recv_ack(deadline, &mut |a| {
                if a.seq == k {
                    seen |= probe_bit(a.probe);
                    send_ns = a.send_ns;
                    last_recv_ns = last_recv_ns.max(a.recv_ns);
                }
            })?;
            if n == 0 {
                return Err(BenchError::Timeout(format!(
                    "message {k} was not acknowledged within {timeout:?}"
                )));
            }
        }
        if k >= warm as u64 {
            let latency = last_recv_ns.saturating_sub(send_ns);
            out.latency.push(latency);
            out.handoff.push(latency + times.loan_ns);
            out.fill.push(times.fill_ns);
        }
    }
    link.send(STOP, None, false)?;
    Ok(out)
}

/// Publishes flat out for `duration` (header only: the hand-off, not the payload writing), then
/// asks the sink for its totals.
pub(crate) fn drive_throughput(
    link: &mut dyn Link,
    duration: Duration,
    timeout: Duration,
) -> Result<ThroughputSamples, BenchError> {
    let start = Instant::now();
    let mut sent = 0u64;
    while start.elapsed() < duration {
        link.send(sent, None, false)?;
        sent += 1;
    }
    let send_secs = start.elapsed().as_secs_f64();
    link.send(STOP, None, false)?;
    let deadline = Instant::now() + timeout;
    let mut totals = None;
    while totals.is_none() {
        let n = link.recv_ack(deadline, &mut |a| {
            if a.seq == STOP {
                totals = Some(*a);
            }
        })?;
        if n == 0 {
            return Err(BenchError::Timeout(
                "the throughput sink did not report its totals".to_string(),
            ));
        }
    }
    let totals = totals.ok_or_else(|| BenchError::Internal("no totals".to_string()))?;
    Ok(ThroughputSamples {
        sent,
        send_secs,
        totals,
    })
}

/// Sends hand-shake rounds into the chain until one comes out at the end.
pub(crate) fn chain_handshake(link: &mut dyn Link, deadline: Instant) -> Result<(), BenchError> {
    for round in 0u64.. {
        let seq = WARMUP + round;
        link.send(seq, None, false)?;
        let round_end = Instant::now() + ROUND * 5;
        let mut through = false;
        while Instant::now() < round_end && !through {
            link.recv(round_end, &mut |r| through |= r.seq == seq)?;
        }
        if through {
            return Ok(());
        }
        if Instant::now() >= deadline {
            break;
        }
    }
    Err(BenchError::Startup(
        "the event chain did not pass a message through in time".to_string(),
    ))
}

/// Sends `warm + samples` messages into the chain, one in flight, each right after the previous
/// came out (`period` None: flat out) or on a fixed period; returns origin → end latencies (ns).
pub(crate) fn drive_chain(
    link: &mut dyn Link,
    first_seq: u64,
    warm: usize,
    samples: usize,
    period: Option<Duration>,
    timeout: Duration,
) -> Result<Vec<u64>, BenchError> {
    let mut out = Vec::with_capacity(samples);
    let start = Instant::now();
    for i in 0..(warm + samples) as u32 {
        if let Some(period) = period {
            let due = start + period * i;
            let now = Instant::now();
            if due > now {
                std::thread::sleep(due - now);
            }
        }
        let seq = first_seq + u64::from(i);
        link.send(seq, None, false)?;
        let deadline = Instant::now() + timeout;
        let mut latency = None;
        while latency.is_none() {
            let n = link.recv(deadline, &mut |r| {
                if r.seq == seq {
                    latency = Some(r.recv_ns.saturating_sub(r.origin_ns));
                }
            })?;
            if n == 0 {
                return Err(BenchError::Timeout(format!(
                    "message {seq} did not come out of the chain within {timeout:?}"
                )));
            }
        }
        if i as usize >= warm
            && let Some(latency) = latency
        {
            out.push(latency);
        }
    }
    Ok(out)
}

/// The probe side of latency and fan-out (`count_only` false: acknowledges every message) and
/// of throughput (`count_only` true: counts, acknowledges hand-shakes and the final totals).
/// Returns at [`STOP`]; fails after `idle` without any message (the driver is gone).
pub(crate) fn echo(
    link: &mut dyn Link,
    probe: u32,
    count_only: bool,
    idle: Duration,
) -> Result<(), BenchError> {
    let mut pending: Vec<Received> = Vec::with_capacity(64);
    let (mut count, mut first_ns, mut last_ns) = (0u64, 0u64, 0u64);
    loop {
        pending.clear();
        let n = link.recv(Instant::now() + idle, &mut |r| pending.push(r))?;
        if n == 0 {
            return Err(BenchError::Timeout(format!(
                "no message for {idle:?}: the driver is gone"
            )));
        }
        for r in &pending {
            if r.seq == STOP {
                if count_only {
                    link.send_ack(&BenchAck {
                        seq: STOP,
                        recv_ns: last_ns,
                        first_ns,
                        count,
                        probe,
                        ..BenchAck::default()
                    })?;
                }
                return Ok(());
            }
            if count_only && r.seq < WARMUP {
                if count == 0 {
                    first_ns = r.recv_ns;
                }
                count += 1;
                last_ns = r.recv_ns;
                continue;
            }
            link.send_ack(&BenchAck {
                seq: r.seq,
                send_ns: r.send_ns,
                recv_ns: r.recv_ns,
                probe,
                ..BenchAck::default()
            })?;
        }
    }
}

/// One hop of the event chain: republishes every message (keeping its origin) on the next
/// topic; forwards [`STOP`] and returns.
pub(crate) fn hop(link: &mut dyn Link, idle: Duration) -> Result<(), BenchError> {
    let mut pending: Vec<Received> = Vec::with_capacity(16);
    loop {
        pending.clear();
        let n = link.recv(Instant::now() + idle, &mut |r| pending.push(r))?;
        if n == 0 {
            return Err(BenchError::Timeout(format!(
                "no message for {idle:?}: the driver is gone"
            )));
        }
        for r in &pending {
            link.send(r.seq, Some(r.origin_ns), false)?;
            if r.seq == STOP {
                return Ok(());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::link::SendTimes;
    use std::collections::VecDeque;

    /// A loop-back link: what is sent comes back as data and is acknowledged by `probes`
    /// simulated probes, with fixed delays.
    struct Loopback {
        probes: u32,
        now: u64,
        data: VecDeque<Received>,
        acks: VecDeque<BenchAck>,
        sent: Vec<u64>,
        sent_at: Vec<Instant>,
    }

    impl Link for Loopback {
        fn send(
            &mut self,
            seq: u64,
            origin_ns: Option<u64>,
            _fill: bool,
        ) -> Result<SendTimes, BenchError> {
            self.now += 1000;
            self.sent.push(seq);
            self.sent_at.push(Instant::now());
            let send_ns = self.now;
            self.data.push_back(Received {
                seq,
                send_ns,
                origin_ns: origin_ns.unwrap_or(send_ns - 100),
                recv_ns: send_ns + 400,
            });
            for p in 0..self.probes {
                self.acks.push_back(BenchAck {
                    seq,
                    send_ns,
                    recv_ns: send_ns + 500 + 100 * u64::from(p),
                    probe: p,
                    ..BenchAck::default()
                });
            }
            Ok(SendTimes {
                loan_ns: 50,
                fill_ns: 7,
            })
        }
        fn recv(
            &mut self,
            _deadline: Instant,
            on: &mut dyn FnMut(Received),
        ) -> Result<usize, BenchError> {
            let n = self.data.len();
            self.data.drain(..).for_each(on);
            Ok(n)
        }
        fn send_ack(&mut self, ack: &BenchAck) -> Result<(), BenchError> {
            self.acks.push_back(*ack);
            Ok(())
        }
        fn recv_ack(
            &mut self,
            _deadline: Instant,
            on: &mut dyn FnMut(&BenchAck),
        ) -> Result<usize, BenchError> {
            let n = self.acks.len();
            self.acks.drain(..).for_each(|a| on(&a));
            Ok(n)
        }
    }

    fn loopback(probes: u32) -> Loopback {
        Loopback {
            probes,
            now: 0,
            data: VecDeque::new(),
            acks: VecDeque::new(),
            sent: Vec::new(),
            sent_at: Vec::new(),
        }
    }

    #[test]
    fn latency_is_to_the_last_probe_and_handoff_adds_the_loan() {
        let mut link = loopback(3);
        handshake(&mut link, 3, Instant::now() + Duration::from_secs(1)).expect("handshake");
        let s = drive_latency(&mut link, 3, 2, 5, None, Duration::from_secs(1)).expect("latency");
        assert_eq!(s.latency, vec![700; 5], "the slowest of three probes");
        assert_eq!(s.handoff, vec![750; 5]);
        assert_eq!(s.fill, vec![7; 5]);
        assert_eq!(link.sent.last(), Some(&STOP));
    }

    #[test]
    fn paced_latency_sends_one_message_per_slot() {
        let mut link = loopback(1);
        let period = Duration::from_millis(2);
        let s =
            drive_latency(&mut link, 1, 1, 4, Some(period), Duration::from_secs(1)).expect("paced");
        assert_eq!(s.latency.len(), 4);
        // Five messages in five different slots: at least four boundaries between the first
        // and the last (sleeping never ends early, so this holds on any machine).
        let sends = &link.sent_at[..5];
        assert!(
            sends[4] - sends[0] > period * 3,
            "five sends within {:?}",
            sends[4] - sends[0]
        );
    }

    #[test]
    fn a_missing_probe_is_a_startup_error() {
        let mut link = loopback(1);
        let r = handshake(&mut link, 2, Instant::now() + Duration::from_millis(50));
        assert!(matches!(r, Err(BenchError::Startup(_))));
    }

    #[test]
    fn chain_latency_is_from_the_origin() {
        let mut link = loopback(0);
        chain_handshake(&mut link, Instant::now() + Duration::from_secs(1)).expect("handshake");
        let s = drive_chain(&mut link, 0, 1, 4, None, Duration::from_secs(1)).expect("chain");
        assert_eq!(s, vec![500; 4]);
        let paced = drive_chain(
            &mut link,
            10,
            0,
            2,
            Some(Duration::from_millis(1)),
            Duration::from_secs(1),
        )
        .expect("paced");
        assert_eq!(paced.len(), 2);
    }

    #[test]
    fn the_sink_counts_and_reports_totals_at_stop() {
        // The loop-back echoes what the sink acknowledges into the ack queue: feed it data.
        let mut link = loopback(0);
        for seq in [WARMUP, 0, 1, 2, STOP] {
            link.data.push_back(Received {
                seq,
                send_ns: 1,
                origin_ns: 1,
                recv_ns: 10 + seq.min(100),
            });
        }
        echo(&mut link, 0, true, Duration::from_secs(1)).expect("sink");
        let acks: Vec<BenchAck> = link.acks.drain(..).collect();
        assert_eq!(acks.len(), 2, "the hand-shake and the totals");
        assert_eq!(acks[0].seq, WARMUP);
        assert_eq!((acks[1].seq, acks[1].count), (STOP, 3));
        assert_eq!((acks[1].first_ns, acks[1].recv_ns), (10, 12));
    }
}
