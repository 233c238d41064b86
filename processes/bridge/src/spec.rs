//! What a bridge carries and where it connects: topics out and in, the peer's namespace, the
//! zenoh endpoints, TLS; checked by the rules of [`mole_types::link`], which the launcher applies
//! to a launch file's `[bridge]` table too.

use mole_runtime::BadInput;
use mole_types::link::{self, Endpoint, LinkError};
use mole_types::topics;
use std::path::PathBuf;

/// The zenoh key of `topic` in `namespace`: `mole/<namespace>/<topic>`, the iceoryx2 service
/// name, so a topic has one name on both sides of the link.
#[must_use]
pub fn key_expr(namespace: &str, topic: &str) -> String {
    topics::service_name(namespace, topic)
}

/// What a listening bridge logs before each endpoint it listens on (port 0 replaced by the
/// port it got): "listening on tcp/127.0.0.1:40123".
pub const LISTENING: &str = "listening on";

/// TLS: the certificate authority both sides trust, and this side's certificate and key (used
/// to listen and to connect; each side checks the other's: mutual TLS).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Tls {
    pub root_ca: PathBuf,
    pub cert: PathBuf,
    pub key: PathBuf,
}

/// The checked settings of the command line: this stack's `namespace`, the peer's, the topics
/// `[out, in]`, the endpoints `[listen, connect]` and the TLS files `[root CA, certificate, key]`
/// (all three or none); a bad one is the launch file's (exit 2).
pub fn spec_of(
    namespace: &str,
    peer_namespace: &str,
    [out, inbound]: [&[String]; 2],
    [listen, connect]: [&[String]; 2],
    tls: [&Option<PathBuf>; 3],
) -> Result<BridgeSpec, BadInput> {
    let tls = match tls {
        [Some(root_ca), Some(cert), Some(key)] => {
            for (what, path) in [
                ("--tls-root-ca", root_ca),
                ("--tls-cert", cert),
                ("--tls-key", key),
            ] {
                if !path.is_file() {
                    return Err(BadInput(format!("{what} {}: no such file", path.display())));
                }
            }
            Some(Tls {
                root_ca: root_ca.clone(),
                cert: cert.clone(),
                key: key.clone(),
            })
        }
        _ => None,
    };
    BridgeSpec::new(
        namespace,
        peer_namespace,
        out,
        inbound,
        listen,
        connect,
        tls,
    )
    .map_err(|e| BadInput(format!("bridge: {e}")))
}

/// A checked bridge.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BridgeSpec {
    /// This stack's namespace.
    pub namespace: String,
    /// The namespace of the stack on the other side: topics in are read under its keys.
    pub peer_namespace: String,
    /// Topics published here and sent to the peer.
    pub out: Vec<&'static str>,
    /// Topics the peer publishes, published here.
    pub inbound: Vec<&'static str>,
    pub listen: Vec<Endpoint>,
    pub connect: Vec<Endpoint>,
    pub tls: Option<Tls>,
}

impl BridgeSpec {
    /// Checks every setting.
    pub fn new(
        namespace: &str,
        peer_namespace: &str,
        out: &[String],
        inbound: &[String],
        listen: &[String],
        connect: &[String],
        tls: Option<Tls>,
    ) -> Result<BridgeSpec, LinkError> {
        if peer_namespace.is_empty() {
            return Err(LinkError::NoPeer);
        }
        let (out, inbound) = link::carried(out, inbound)?;
        let (listen, connect) = link::endpoints(listen, connect, tls.is_some())?;
        Ok(BridgeSpec {
            namespace: namespace.to_owned(),
            peer_namespace: peer_namespace.to_owned(),
            out,
            inbound,
            listen,
            connect,
            tls,
        })
    }

    /// Where the bridge looks for its peer, as a phrase: "listening on …; connecting to …".
    #[must_use]
    pub fn whereabouts(&self) -> String {
        let list = |e: &[Endpoint]| match e {
            [] => "nothing".to_owned(),
            e => e
                .iter()
                .map(Endpoint::as_str)
                .collect::<Vec<_>>()
                .join(", "),
        };
        format!(
            "listening on {}; connecting to {}",
            list(&self.listen),
            list(&self.connect)
        )
    }

    /// The endpoints listened on, port 0 replaced by the port zenoh bound: `locators` are the
    /// session's (`tcp/127.0.0.1:40123`, a host name resolved, an unspecified host expanded to
    /// each interface). `None` if no locator answers an endpoint of port 0.
    #[must_use]
    pub fn bound(&self, locators: &[String]) -> Option<Vec<Endpoint>> {
        let fixed = |protocol: &str| -> Vec<u16> {
            self.listen
                .iter()
                .filter(|e| e.protocol() == protocol && e.port() != 0)
                .map(Endpoint::port)
                .collect()
        };
        self.listen
            .iter()
            .map(|e| {
                if e.port() != 0 {
                    return Some(e.clone());
                }
                let taken = fixed(e.protocol());
                let literal = e
                    .host()
                    .trim_matches(['[', ']'])
                    .parse::<std::net::IpAddr>();
                locators
                    .iter()
                    .filter_map(|l| l.parse::<Endpoint>().ok())
                    .filter(|l| l.protocol() == e.protocol() && !taken.contains(&l.port()))
                    .find(|l| match &literal {
                        Ok(ip) if !ip.is_unspecified() => l.host() == e.host(),
                        _ => true,
                    })
                    .map(|l| e.with_port(l.port()))
            })
            .collect()
    }

    /// The endpoints to listen on again after a restart, from what the first start wrote
    /// (`recorded`, one endpoint a line: [`BridgeSpec::bound`]), so the other half, which
    /// connects to the port the first start got, finds this one there. `None` if the record is
    /// not of these endpoints.
    #[must_use]
    pub fn listening_again(&self, recorded: &str) -> Option<Vec<Endpoint>> {
        let recorded: Vec<Endpoint> = recorded
            .lines()
            .filter(|l| !l.trim().is_empty())
            .map(|l| l.trim().parse().ok())
            .collect::<Option<_>>()?;
        let same = recorded.len() == self.listen.len()
            && self.listen.iter().zip(&recorded).all(|(e, r)| {
                r.port() != 0
                    && (e.port() == 0 || e.port() == r.port())
                    && e.with_port(0) == r.with_port(0)
            });
        same.then_some(recorded)
    }

    /// The zenoh session's configuration: a peer that listens only on the endpoints given (none
    /// is none, not zenoh's default "any interface"), connects to the others and keeps trying
    /// when they are not up yet or go away, finds nobody by multicast, and with TLS requires
    /// and checks the other side's certificate.
    #[must_use]
    pub fn zenoh_config(&self) -> serde_json::Value {
        let list = |e: &[Endpoint]| e.iter().map(|e| e.as_str().to_owned()).collect::<Vec<_>>();
        let mut config = serde_json::json!({
            "mode": "peer",
            "listen": { "endpoints": list(&self.listen) },
            "connect": {
                "endpoints": list(&self.connect),
                "timeout_ms": -1,
                "exit_on_failure": false,
                "retry": { "period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2 },
            },
            "scouting": { "multicast": { "enabled": false }, "gossip": { "enabled": false } },
        });
        if let Some(tls) = &self.tls {
            let path = |p: &PathBuf| p.display().to_string();
            config["transport"] = serde_json::json!({ "link": { "tls": {
                "root_ca_certificate": path(&tls.root_ca),
                "listen_certificate": path(&tls.cert),
                "listen_private_key": path(&tls.key),
                "connect_certificate": path(&tls.cert),
                "connect_private_key": path(&tls.key),
                "enable_mtls": true,
                "verify_name_on_connect": true,
            }}});
        }
        config
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn strings(list: &[&str]) -> Vec<String> {
        list.iter().map(|s| (*s).to_owned()).collect()
    }

    /// A bridge of robot `a` to `b` that only listens, on `endpoints`.
    fn listening_on(endpoints: &[&str], tls: Option<Tls>) -> BridgeSpec {
        BridgeSpec::new("a", "b", &[], &[], &strings(endpoints), &[], tls).unwrap()
    }

    #[test]
    fn keys_are_the_service_names() {
        assert_eq!(key_expr("robot", "sensing/scan"), "mole/robot/sensing/scan");
    }

    #[test]
    fn the_session_listens_only_where_told_and_scouts_nobody() {
        let connect_only = BridgeSpec::new(
            "a",
            "b",
            &[],
            &[],
            &[],
            &strings(&["tcp/10.0.0.2:7447"]),
            None,
        )
        .unwrap();
        let config = connect_only.zenoh_config();
        assert_eq!(config["listen"]["endpoints"], serde_json::json!([]));
        assert_eq!(
            config["connect"]["endpoints"],
            serde_json::json!(["tcp/10.0.0.2:7447"])
        );
        assert_eq!(config["scouting"]["multicast"]["enabled"], false);
        assert!(config.get("transport").is_none());
    }

    #[test]
    fn port_zero_is_reported_as_the_port_zenoh_bound() {
        let spec = listening_on(&["tcp/127.0.0.1:7447", "tcp/localhost:0"], None);
        let locators = strings(&["tcp/127.0.0.1:7447", "tcp/127.0.0.1:40123"]);
        let bound = spec.bound(&locators).expect("both bound");
        let bound: Vec<&str> = bound.iter().map(Endpoint::as_str).collect();
        assert_eq!(bound, ["tcp/127.0.0.1:7447", "tcp/localhost:40123"]);
        assert_eq!(spec.bound(&strings(&["tcp/127.0.0.1:7447"])), None);

        let literal = BridgeSpec::new(
            "a",
            "b",
            &[],
            &[],
            &strings(&["tls/[::1]:0"]),
            &[],
            Some(tls()),
        )
        .unwrap();
        let bound = literal.bound(&strings(&["tls/10.0.0.1:5000", "tls/[::1]:5001"]));
        assert_eq!(bound, Some(vec!["tls/[::1]:5001".parse().unwrap()]));
    }

    #[test]
    fn a_restart_listens_again_where_the_first_start_did() {
        let spec = listening_on(&["tcp/127.0.0.1:7447", "tcp/localhost:0"], None);
        let again = spec
            .listening_again("tcp/127.0.0.1:7447\ntcp/localhost:40123\n")
            .expect("the first start's record");
        assert_eq!(again[1].as_str(), "tcp/localhost:40123");
        for foreign in [
            "tcp/127.0.0.1:7447\n",
            "tcp/127.0.0.1:7447\ntcp/10.0.0.1:40123\n",
            "tcp/127.0.0.1:7448\ntcp/localhost:40123\n",
            "tcp/127.0.0.1:7447\ntcp/localhost:0\n",
            "not an endpoint\n",
        ] {
            assert_eq!(spec.listening_again(foreign), None, "{foreign}");
        }
    }

    fn tls() -> Tls {
        Tls {
            root_ca: "ca.pem".into(),
            cert: "me.pem".into(),
            key: "me.key".into(),
        }
    }

    #[test]
    fn tls_requires_the_peers_certificate() {
        let spec = listening_on(&["tls/127.0.0.1:7447"], Some(tls()));
        let tls = &spec.zenoh_config()["transport"]["link"]["tls"];
        assert_eq!(tls["enable_mtls"], true);
        assert_eq!(tls["root_ca_certificate"], "ca.pem");
    }
}
