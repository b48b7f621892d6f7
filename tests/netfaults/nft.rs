//! nftables tables inside a namespace: loss, partition, duplication, each with named
//! counters of what it saw and did.

use std::collections::BTreeMap;

use serde_json::Value;

use crate::netns::Netns;

/// One nftables table inside a namespace; deleted on drop (the namespace's deletion
/// would remove it too: this makes a partition end, and states the intent).
pub(super) struct NftTable {
    pub(super) ns: String,
    family: &'static str,
    pub(super) name: &'static str,
}

impl NftTable {
    /// Loads `body` (the table's chains and counters) as `table FAMILY NAME { BODY }`.
    fn add(ns: &str, family: &'static str, name: &'static str, body: &str) -> Self {
        let text = format!("table {family} {name} {{\n{body}\n}}\n");
        Netns::exec(ns, "nft", &["-f", "-"], &text).unwrap_or_else(|e| panic!("{e}"));
        Self {
            ns: ns.to_string(),
            family,
            name,
        }
    }

    /// The table's named counters: name → packets.
    pub(super) fn counters(&self) -> BTreeMap<String, u64> {
        let out = Netns::exec(
            &self.ns,
            "nft",
            &["-j", "list", "counters", "table", self.family, self.name],
            "",
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let v: Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"));
        v["nftables"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(|o| {
                let c = o.get("counter")?;
                Some((c["name"].as_str()?.to_string(), c["packets"].as_u64()?))
            })
            .collect()
    }
}

impl Drop for NftTable {
    fn drop(&mut self) {
        let _ = Netns::exec(
            &self.ns,
            "nft",
            &["delete", "table", self.family, self.name],
            "",
        );
    }
}

/// Drops `percent` % of the TCP packets in each direction on the agents' veth end,
/// counting what it saw and dropped.
pub(super) fn loss_table(ns: &Netns, percent: u32) -> NftTable {
    let dev = &ns.agents;
    NftTable::add(
        &ns.agents,
        "inet",
        "vrloss",
        &format!(
            "counter seen_in {{}}\ncounter dropped_in {{}}\n\
             counter seen_out {{}}\ncounter dropped_out {{}}\n\
             chain in {{\ntype filter hook input priority 0; policy accept;\n\
             iifname {dev:?} meta l4proto tcp counter name \"seen_in\"\n\
             iifname {dev:?} meta l4proto tcp numgen random mod 100 < {percent} \
             counter name \"dropped_in\" drop\n}}\n\
             chain out {{\ntype filter hook output priority 0; policy accept;\n\
             oifname {dev:?} meta l4proto tcp counter name \"seen_out\"\n\
             oifname {dev:?} meta l4proto tcp numgen random mod 100 < {percent} \
             counter name \"dropped_out\" drop\n}}"
        ),
    )
}

/// Drops every packet on the agents' veth end, both ways, while it exists.
pub(super) fn partition_table(ns: &Netns) -> NftTable {
    let dev = &ns.agents;
    NftTable::add(
        &ns.agents,
        "inet",
        "vrpartition",
        &format!(
            "counter dropped {{}}\n\
             chain in {{\ntype filter hook input priority -10; policy accept;\n\
             iifname {dev:?} counter name \"dropped\" drop\n}}\n\
             chain out {{\ntype filter hook output priority -10; policy accept;\n\
             oifname {dev:?} counter name \"dropped\" drop\n}}"
        ),
    )
}

/// Drops the packets that carry data towards one side only, on the agents' veth end,
/// while it exists: towards the host, the agents' output; towards the agents, their
/// input. Bare acknowledgements (52 bytes: IPv4, TCP with timestamps) pass, so the other
/// direction keeps flowing: the side that receives nothing sees its lease run out and
/// closes the link while the other side still hears it. Connection attempts (a SYN
/// carries options: 60 bytes) are dropped too.
pub(super) fn one_way_table(ns: &Netns, towards: super::Towards) -> NftTable {
    let dev = &ns.agents;
    let (hook, dir) = match towards {
        super::Towards::Host => ("output", "oifname"),
        super::Towards::Agents => ("input", "iifname"),
    };
    NftTable::add(
        &ns.agents,
        "inet",
        "vroneway",
        &format!(
            "counter dropped {{}}\n\
             chain c {{\ntype filter hook {hook} priority -10; policy accept;\n\
             {dir} {dev:?} meta l4proto tcp ip length > 52 counter name \"dropped\" drop\n}}"
        ),
    )
}

/// Sends a second copy of `percent` % of the packets leaving `ns_name` through `dev`
/// towards `peer` (nftables `dup` in the output hook).
pub(super) fn duplicate_table(ns_name: &str, dev: &str, peer: &str, percent: u32) -> NftTable {
    NftTable::add(
        ns_name,
        "ip",
        "vrdup",
        &format!(
            "counter seen {{}}\ncounter duplicated {{}}\n\
             chain out {{\ntype filter hook output priority 0; policy accept;\n\
             oifname {dev:?} ip daddr {peer} counter name \"seen\"\n\
             oifname {dev:?} ip daddr {peer} numgen random mod 100 < {percent} \
             counter name \"duplicated\" dup to {peer} device {dev:?}\n}}"
        ),
    )
}

/// Marks `percent` % of the packets leaving `ns_name` towards `peer` (`meta mark set
/// mark`) in a route chain, so that the kernel routes them again by their mark.
pub(super) fn reorder_table(ns_name: &str, peer: &str, percent: u32, mark: u32) -> NftTable {
    NftTable::add(
        ns_name,
        "ip",
        "vrreorder",
        &format!(
            "counter seen {{}}\ncounter slowed {{}}\n\
             chain out {{\ntype route hook output priority 0; policy accept;\n\
             ip daddr {peer} counter name \"seen\"\n\
             ip daddr {peer} numgen random mod 100 < {percent} \
             meta mark set {mark} counter name \"slowed\"\n}}"
        ),
    )
}
