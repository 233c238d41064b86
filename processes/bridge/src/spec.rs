//! What a bridge carries and where it connects: topics out and in, the peer's namespace, the
//! zenoh endpoints, TLS; checked by the rules of [`mole_types::link`], which the launcher applies
//! to a launch file's `[bridge]` table too.

use mole_types::link::{self, Endpoint, LinkError};
use mole_types::topics;
use std::path::PathBuf;

/// The zenoh key of `topic` in `namespace`: `mole/<namespace>/<topic>`, the iceoryx2 service
/// name, so a topic has one name on both sides of the link.
#[must_use]
pub fn key_expr(namespace: &str, topic: &str) -> String {
    topics::service_name(namespace, topic)
}

/// TLS: the certificate authority both sides trust, and this side's certificate and key (used
/// to listen and to connect; each side checks the other's: mutual TLS).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Tls {
    pub root_ca: PathBuf,
    pub cert: PathBuf,
    pub key: PathBuf,
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
    fn tls_requires_the_peers_certificate() {
        let tls = Tls {
            root_ca: "ca.pem".into(),
            cert: "me.pem".into(),
            key: "me.key".into(),
        };
        let spec = BridgeSpec::new(
            "a",
            "b",
            &[],
            &[],
            &strings(&["tls/127.0.0.1:7447"]),
            &[],
            Some(tls),
        )
        .unwrap();
        let tls = &spec.zenoh_config()["transport"]["link"]["tls"];
        assert_eq!(tls["enable_mtls"], true);
        assert_eq!(tls["root_ca_certificate"], "ca.pem");
    }
}
