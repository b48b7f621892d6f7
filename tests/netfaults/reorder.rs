//! Packet reordering on a kernel without netem: a second, slower path between the two
//! namespaces that a random share of the packets takes, so that they arrive behind
//! packets sent after them.
//!
//! - A second veth pair, `slow`, between the namespaces, each end shaped by a token
//!   bucket (`tc qdisc add dev slow root tbf rate R burst B latency L`): a packet sent
//!   through it waits for its tokens, behind the other packets queued there, while the
//!   packets after it go on over the first veth pair at once.
//! - In each namespace an nftables `type route hook output` chain marks P % of the
//!   packets to the other side's address (`numgen random mod 100 < P meta mark set 1`);
//!   a route chain makes the kernel look the route up again after a mark changed.
//! - `ip rule add fwmark 1 table 100` and `ip route add <peer>/32 dev slow table 100`
//!   send the marked packets through `slow`. The addresses stay those of the first veth
//!   pair (`slow` has none), so the sockets see one link; reverse-path filtering is off
//!   on the receiving side (a packet from the peer comes in on a device its route does
//!   not leave through).
//!
//! The first veth pair keeps no qdisc: the unmarked packets travel as on the clean link.
//! (An HTB qdisc on the first veth pair with a slow class chosen by `meta priority set`
//! reorders too, with no second link, but queues every packet behind HTB's shaping.)
//!
//! What shows that packets were reordered: the TCP stacks' own counters in each
//! namespace (`/proc/net/netstat`, `/proc/net/snmp`), before and after the run:
//! `TCPOFOQueue` (segments the receiver queued out of order), `TCPSACKReorder` and
//! `TCPTSReorder` (reordering the sender detected), `TCPDSACKRecv` (retransmissions the
//! receiver said were not needed), `RetransSegs`.

use std::collections::BTreeMap;

use super::nft::{NftTable, reorder_table};
use crate::netns::{AGENT_IP, HOST_IP, Netns};

/// The slow path's device, in both namespaces (one end of the second veth pair in each).
const SLOW_DEV: &str = "slow";
/// The firewall mark of the packets that take the slow path, and its routing table.
const MARK: u32 = 1;
const TABLE: &str = "100";
/// The slow path's token bucket: 10 Mbit/s, one full-size packet of burst (a packet
/// behind another waits ~1.2 ms per packet ahead of it), at most 200 ms queued (beyond
/// that it would drop: counted as `tbf_dropped`).
const TBF: [&str; 6] = ["rate", "10mbit", "burst", "1600", "latency", "200ms"];
/// The TCP counters reported, from `/proc/net/netstat`'s `TcpExt` and `/proc/net/snmp`'s
/// `Tcp` lines.
const TCP_COUNTERS: [&str; 6] = [
    "TCPOFOQueue",
    "TCPSACKReorder",
    "TCPTSReorder",
    "TCPDSACKRecv",
    "TCPDSACKOldSent",
    "RetransSegs",
];

/// The slow path and its rules while it exists: removed on drop (deleting the namespaces
/// removes all of it too, when a test fails before).
pub(super) struct Reorder {
    /// (namespace, "host" or "agents").
    sides: [(String, &'static str); 2],
    tables: Vec<NftTable>,
    /// The TCP counters of each side when the slow path was set up.
    before: BTreeMap<String, u64>,
}

impl Reorder {
    /// Sends `percent` % of the packets each way through the slow path.
    pub(super) fn install(ns: &Netns, percent: u32) -> Self {
        let mut this = Self {
            sides: [(ns.host.clone(), "host"), (ns.agents.clone(), "agents")],
            tables: Vec::new(),
            before: BTreeMap::new(),
        };
        let run = |side: &str, program: &str, args: &[&str]| {
            Netns::exec(side, program, args, "").unwrap_or_else(|e| panic!("{e}"));
        };
        // Both ends made inside the namespaces: nothing of it ever sits in the test's own.
        run(
            &ns.host,
            "ip",
            &[
                "link", "add", SLOW_DEV, "type", "veth", "peer", "name", SLOW_DEV, "netns",
                &ns.agents,
            ],
        );
        let mark = MARK.to_string();
        for (side, peer) in [(&ns.host, AGENT_IP), (&ns.agents, HOST_IP)] {
            run(side, "ip", &["link", "set", SLOW_DEV, "gso_max_segs", "1"]);
            run(side, "ip", &["link", "set", SLOW_DEV, "up"]);
            let mut tc = vec!["qdisc", "add", "dev", SLOW_DEV, "root", "tbf"];
            tc.extend(TBF);
            run(side, "tc", &tc);
            for dev in ["all", SLOW_DEV] {
                run(
                    side,
                    "sysctl",
                    &["-qw", &format!("net.ipv4.conf.{dev}.rp_filter=0")],
                );
            }
            let peer_route = format!("{peer}/32");
            run(
                side,
                "ip",
                &["route", "add", &peer_route, "dev", SLOW_DEV, "table", TABLE],
            );
            run(
                side,
                "ip",
                &["rule", "add", "fwmark", &mark, "table", TABLE],
            );
            this.tables.push(reorder_table(side, peer, percent, MARK));
        }
        this.before = this.tcp_counters();
        this
    }

    /// Per side: the nftables counters (packets seen, sent the slow way), what the token
    /// bucket dropped, and how much each TCP counter grew since [`Reorder::install`].
    pub(super) fn counters(&self) -> BTreeMap<String, u64> {
        let mut out = BTreeMap::new();
        for t in &self.tables {
            let side = self.side_name(&t.ns);
            for (k, v) in t.counters() {
                out.insert(format!("{side}.{k}"), v);
            }
        }
        for (ns, side) in &self.sides {
            out.insert(format!("{side}.tbf_dropped"), tbf_dropped(ns));
        }
        for (k, v) in self.tcp_counters() {
            let grew = v.saturating_sub(self.before.get(&k).copied().unwrap_or(0));
            out.insert(k, grew);
        }
        out
    }

    fn side_name(&self, ns: &str) -> &'static str {
        self.sides
            .iter()
            .find(|(n, _)| n == ns)
            .map_or("?", |(_, s)| s)
    }

    /// `side.Counter` → value now, for [`TCP_COUNTERS`] in both namespaces.
    fn tcp_counters(&self) -> BTreeMap<String, u64> {
        let mut out = BTreeMap::new();
        for (ns, side) in &self.sides {
            for file in ["/proc/net/netstat", "/proc/net/snmp"] {
                let text = Netns::exec(ns, "cat", &[file], "").unwrap_or_else(|e| panic!("{e}"));
                for (k, v) in proc_net_counters(&text) {
                    if TCP_COUNTERS.contains(&k.as_str()) {
                        out.insert(format!("{side}.{k}"), v);
                    }
                }
            }
        }
        out
    }
}

impl Drop for Reorder {
    fn drop(&mut self) {
        // The nftables tables go with `self.tables`; deleting one end of the veth pair
        // deletes the other, its qdiscs and table 100's routes.
        let mark = MARK.to_string();
        for (ns, _) in &self.sides {
            let _ = Netns::exec(
                ns,
                "ip",
                &["rule", "del", "fwmark", &mark, "table", TABLE],
                "",
            );
        }
        let _ = Netns::exec(&self.sides[0].0, "ip", &["link", "del", SLOW_DEV], "");
    }
}

/// Packets the slow path's token bucket in `ns` dropped (`tc -s -j qdisc`).
fn tbf_dropped(ns: &str) -> u64 {
    let out = Netns::exec(
        ns,
        "tc",
        &["-s", "-j", "qdisc", "show", "dev", SLOW_DEV],
        "",
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let v: serde_json::Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"));
    v.as_array()
        .into_iter()
        .flatten()
        .filter(|q| q["kind"] == "tbf")
        .filter_map(|q| q["drops"].as_u64())
        .sum()
}

/// The counters of a `/proc/net/netstat` or `/proc/net/snmp` text: pairs of lines, names
/// then values, each starting with the same `Prefix:`.
fn proc_net_counters(text: &str) -> Vec<(String, u64)> {
    let lines: Vec<&str> = text.lines().collect();
    lines
        .chunks(2)
        .filter(|pair| pair.len() == 2)
        .flat_map(|pair| {
            let names = pair[0].split_whitespace().skip(1);
            let values = pair[1].split_whitespace().skip(1);
            names
                .zip(values)
                .filter_map(|(n, v)| Some((n.to_string(), v.parse().ok()?)))
                .collect::<Vec<_>>()
        })
        .collect()
}

#[test]
fn proc_net_counters_pairs_names_with_values() {
    let text = "TcpExt: SyncookiesSent TCPOFOQueue\nTcpExt: 0 17\n\
                Tcp: RtoAlgorithm RetransSegs\nTcp: 1 4\n";
    let expected = [
        ("SyncookiesSent", 0),
        ("TCPOFOQueue", 17),
        ("RtoAlgorithm", 1),
        ("RetransSegs", 4),
    ]
    .map(|(n, v)| (n.to_string(), v));
    assert_eq!(proc_net_counters(text), expected);
}
