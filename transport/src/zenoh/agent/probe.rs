//! Whether a host whose token vanished without its close is still there: a plain TCP
//! connect to its `tcp/` and `tls/` connect endpoints (see the agent module's docs).

use std::time::Duration;

/// How often an agent whose host's token vanished without its close tries the host's
/// address (see the module docs).
pub const PROBE_PERIOD: Duration = Duration::from_millis(500);
/// How long one try of the host's address may take: a link that drops packets does not
/// answer at all, a machine whose port nothing listens on answers at once.
pub const PROBE_TIMEOUT: Duration = Duration::from_millis(200);

/// The socket addresses (`host:port`) of the `tcp/` and `tls/` endpoints in `connect`
/// (zenoh's metadata after `?` or `#` dropped); other protocols are skipped.
pub(in crate::zenoh) fn probe_addresses(connect: &[String]) -> Vec<String> {
    connect
        .iter()
        .filter_map(|e| e.strip_prefix("tcp/").or_else(|| e.strip_prefix("tls/")))
        .map(|a| a.split(['?', '#']).next().unwrap_or(a).to_string())
        .collect()
}

/// Whether every address in `addresses` refuses a TCP connection (at least one address,
/// each resolved, each of its socket addresses refusing): the host's machine answers and
/// nothing listens there, so the host's process is gone. A timeout or any other error
/// (a lost link) is not a refusal.
pub(super) fn every_address_refuses(addresses: &[String]) -> Option<String> {
    use std::net::ToSocketAddrs;
    if addresses.is_empty() {
        return None;
    }
    let mut refused = Vec::new();
    for a in addresses {
        let resolved: Vec<_> = a.to_socket_addrs().ok()?.collect();
        if resolved.is_empty() {
            return None;
        }
        for addr in resolved {
            match std::net::TcpStream::connect_timeout(&addr, PROBE_TIMEOUT) {
                Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => {
                    refused.push(addr.to_string());
                }
                _ => return None,
            }
        }
    }
    Some(refused.join(", "))
}
