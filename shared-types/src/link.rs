//! A stack split across machines: which topics a bridge may carry and what a zenoh endpoint
//! looks like. The launcher checks a launch file's `[bridge]` table with these (naming the file
//! and field), the bridge (`mole-bridge`) its command line.

use crate::topics;
use core::time::Duration;

/// How long a bridge waits for its peer's bridge when it starts; then it ends (exit 2) saying
/// what it saw on the link. Both halves' bridges wait the same, so a mismatched pair ends on
/// both sides.
pub const PEER_TIMEOUT: Duration = Duration::from_secs(20);

/// The file, in the run's output directory, where a listening bridge writes the endpoints it
/// listens on (one a line, port 0 replaced by the port it got), as the other half connects to
/// them.
pub const LISTENING_FILE: &str = "bridge-listening.txt";

/// Topics each host keeps to itself: every launcher supervises its own processes.
pub const PER_HOST: [&str; 2] = [topics::STACK_STATS.name, topics::STACK_PROCESSES.name];

/// A bridge setting that cannot work.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LinkError {
    UnknownTopic(String),
    PerHost(String),
    BothWays(String),
    Endpoint(String),
    ConnectPortZero(String),
    PortZeroTwice(String, String),
    NoEndpoint,
    TlsMissing(String),
    TlsUnused,
    NoPeer,
}

impl core::fmt::Display for LinkError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            LinkError::UnknownTopic(t) => {
                write!(
                    f,
                    "unknown topic `{t}`, expected one of: {}",
                    carried_topics().join(", ")
                )
            }
            LinkError::PerHost(t) => write!(
                f,
                "topic `{t}` is per host (each launcher supervises its own processes), expected a topic of the stack's dataflow"
            ),
            LinkError::BothWays(t) => write!(
                f,
                "topic `{t}` is both carried out and in, expected each topic in one direction"
            ),
            LinkError::Endpoint(e) => {
                write!(f, "endpoint `{e}`: expected tcp/HOST:PORT or tls/HOST:PORT")
            }
            LinkError::ConnectPortZero(e) => write!(
                f,
                "endpoint `{e}`: port 0 is for listening (the bridge reports the port it got), expected the port the other half listens on"
            ),
            LinkError::PortZeroTwice(a, b) => write!(
                f,
                "endpoints `{a}` and `{b}` both listen on port 0, expected at most one (its port is reported: see {LISTENING_FILE})"
            ),
            LinkError::NoEndpoint => {
                write!(
                    f,
                    "no endpoint: expected at least one to listen on or connect to"
                )
            }
            LinkError::TlsMissing(e) => write!(
                f,
                "endpoint `{e}` is tls/ but no TLS certificate is set, expected tls = {{ root_ca, cert, key }}"
            ),
            LinkError::TlsUnused => write!(
                f,
                "TLS is set but every endpoint is tcp/, expected tls/ endpoints (or no TLS settings)"
            ),
            LinkError::NoPeer => write!(
                f,
                "the peer's namespace is empty, expected the namespace of the stack on the other side"
            ),
        }
    }
}

impl std::error::Error for LinkError {}

/// Every topic a bridge may carry, in table order.
#[must_use]
pub fn carried_topics() -> Vec<&'static str> {
    topics::all()
        .into_iter()
        .map(|(name, _)| name)
        .filter(|name| !PER_HOST.contains(name))
        .collect()
}

/// The topic of the table named `name`, if a bridge may carry it.
pub fn carried_topic(name: &str) -> Result<&'static str, LinkError> {
    let known = topics::all()
        .into_iter()
        .map(|(topic, _)| topic)
        .find(|topic| *topic == name)
        .ok_or_else(|| LinkError::UnknownTopic(name.to_owned()))?;
    if PER_HOST.contains(&known) {
        return Err(LinkError::PerHost(name.to_owned()));
    }
    Ok(known)
}

/// Topics carried out and in, checked: known, not per host, each in one direction.
pub fn carried(
    out: &[String],
    inbound: &[String],
) -> Result<(Vec<&'static str>, Vec<&'static str>), LinkError> {
    let names = |list: &[String]| -> Result<Vec<&'static str>, LinkError> {
        list.iter().map(|n| carried_topic(n)).collect()
    };
    let (out, inbound) = (names(out)?, names(inbound)?);
    if let Some(both) = out.iter().find(|t| inbound.contains(t)) {
        return Err(LinkError::BothWays((*both).to_owned()));
    }
    Ok((out, inbound))
}

/// A zenoh endpoint: `tcp/HOST:PORT` or `tls/HOST:PORT` (HOST a name, an IPv4 address or a
/// bracketed IPv6 one).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Endpoint(String);

impl Endpoint {
    /// Whether the endpoint is TLS.
    #[must_use]
    pub fn is_tls(&self) -> bool {
        self.0.starts_with("tls/")
    }

    /// As zenoh writes it.
    #[must_use]
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// `tcp` or `tls`.
    #[must_use]
    pub fn protocol(&self) -> &str {
        self.0.split_once('/').map_or("", |(protocol, _)| protocol)
    }

    /// The host: a name, an IPv4 address or a bracketed IPv6 one.
    #[must_use]
    pub fn host(&self) -> &str {
        self.address().0
    }

    /// The port (0 when listening: any port the system gives).
    #[must_use]
    pub fn port(&self) -> u16 {
        self.address().1
    }

    /// The same endpoint on `port`.
    #[must_use]
    pub fn with_port(&self, port: u16) -> Endpoint {
        Endpoint(format!("{}/{}:{port}", self.protocol(), self.host()))
    }

    fn address(&self) -> (&str, u16) {
        // Checked on parsing: `PROTOCOL/HOST:PORT`.
        let address = self.0.split_once('/').map_or("", |(_, a)| a);
        let (host, port) = address.rsplit_once(':').unwrap_or((address, "0"));
        (host, port.parse().unwrap_or(0))
    }
}

impl core::str::FromStr for Endpoint {
    type Err = LinkError;
    fn from_str(text: &str) -> Result<Endpoint, LinkError> {
        let bad = || LinkError::Endpoint(text.to_owned());
        let address = text
            .strip_prefix("tcp/")
            .or_else(|| text.strip_prefix("tls/"))
            .ok_or_else(bad)?;
        let (host, port) = address.rsplit_once(':').ok_or_else(bad)?;
        let host_ok = !host.is_empty()
            && !host.contains(['/', '#', '?', ' '])
            && (!host.starts_with('[') || host.ends_with(']'));
        if !host_ok || port.parse::<u16>().is_err() {
            return Err(bad());
        }
        Ok(Endpoint(text.to_owned()))
    }
}

/// Endpoints to listen on and connect to, checked: well formed, at least one, port 0 only to
/// listen and on one endpoint at most, and TLS settings given exactly when some endpoint is
/// `tls/`.
pub fn endpoints(
    listen: &[String],
    connect: &[String],
    tls: bool,
) -> Result<(Vec<Endpoint>, Vec<Endpoint>), LinkError> {
    let parse = |list: &[String]| -> Result<Vec<Endpoint>, LinkError> {
        list.iter().map(|e| e.parse()).collect()
    };
    let (listen, connect) = (parse(listen)?, parse(connect)?);
    if listen.is_empty() && connect.is_empty() {
        return Err(LinkError::NoEndpoint);
    }
    if let Some(e) = connect.iter().find(|e| e.port() == 0) {
        return Err(LinkError::ConnectPortZero(e.0.clone()));
    }
    let mut any_port = listen.iter().filter(|e| e.port() == 0);
    if let (Some(a), Some(b)) = (any_port.next(), any_port.next()) {
        return Err(LinkError::PortZeroTwice(a.0.clone(), b.0.clone()));
    }
    match (tls, listen.iter().chain(&connect).find(|e| e.is_tls())) {
        (false, Some(e)) => Err(LinkError::TlsMissing(e.0.clone())),
        (true, None) => Err(LinkError::TlsUnused),
        _ => Ok((listen, connect)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn strings(list: &[&str]) -> Vec<String> {
        list.iter().map(|s| (*s).to_owned()).collect()
    }

    #[test]
    fn topics_are_checked() {
        let (out, inbound) =
            carried(&strings(&["world/truth"]), &strings(&["planning/cmd"])).unwrap();
        assert_eq!((out, inbound), (vec!["world/truth"], vec!["planning/cmd"]));
        assert_eq!(
            carried(&strings(&["world/truht"]), &[]),
            Err(LinkError::UnknownTopic("world/truht".into()))
        );
        assert_eq!(
            carried(&strings(&["stack/stats"]), &[]),
            Err(LinkError::PerHost("stack/stats".into()))
        );
        assert_eq!(
            carried(&strings(&["planning/cmd"]), &strings(&["planning/cmd"])),
            Err(LinkError::BothWays("planning/cmd".into()))
        );
        assert!(!carried_topics().contains(&"stack/stats"));
    }

    #[test]
    fn an_endpoint_has_a_protocol_a_host_and_a_port() {
        let e: Endpoint = "tls/[::1]:0".parse().unwrap();
        assert_eq!((e.protocol(), e.host(), e.port()), ("tls", "[::1]", 0));
        assert_eq!(e.with_port(40123).as_str(), "tls/[::1]:40123");
        assert!(e.is_tls());
    }

    #[test]
    fn endpoints_are_checked() {
        for good in ["tcp/127.0.0.1:7447", "tls/robot.local:1", "tcp/[::1]:7447"] {
            assert!(good.parse::<Endpoint>().is_ok(), "{good}");
        }
        for bad in [
            "udp/127.0.0.1:7447",
            "tcp/127.0.0.1",
            "tcp/:7447",
            "tcp/host:70000",
            "127.0.0.1:7447",
        ] {
            assert_eq!(
                bad.parse::<Endpoint>(),
                Err(LinkError::Endpoint(bad.into())),
                "{bad}"
            );
        }
        assert_eq!(endpoints(&[], &[], false), Err(LinkError::NoEndpoint));
        assert_eq!(
            endpoints(&[], &strings(&["tcp/10.0.0.2:0"]), false),
            Err(LinkError::ConnectPortZero("tcp/10.0.0.2:0".into()))
        );
        assert_eq!(
            endpoints(&strings(&["tcp/127.0.0.1:0", "tcp/[::1]:0"]), &[], false),
            Err(LinkError::PortZeroTwice(
                "tcp/127.0.0.1:0".into(),
                "tcp/[::1]:0".into()
            ))
        );
        assert!(endpoints(&strings(&["tcp/127.0.0.1:0", "tcp/[::1]:7447"]), &[], false).is_ok());
        assert_eq!(
            endpoints(&strings(&["tls/127.0.0.1:7447"]), &[], false),
            Err(LinkError::TlsMissing("tls/127.0.0.1:7447".into()))
        );
        assert_eq!(
            endpoints(&strings(&["tcp/127.0.0.1:7447"]), &[], true),
            Err(LinkError::TlsUnused)
        );
    }
}
