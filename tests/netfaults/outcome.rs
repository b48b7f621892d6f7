//! What one run of the world measured ([`Outcome`]), what a fault the link recovers from
//! must leave intact, the `netfaults:` line each run prints, and the check that every
//! command an agent sent was applied once, in its cycle.

use std::collections::BTreeMap;
use std::path::Path;

use serde_json::Value;

use super::{Fault, Remote};
use crate::util::cycle_log;

/// What one run measured.
#[derive(Debug)]
pub(super) struct Outcome {
    pub(super) remote: Remote,
    pub(super) fault: Fault,
    pub(super) lease_s: f64,
    pub(super) host_code: Option<i32>,
    pub(super) frames: u64,
    /// Cycles per second from all agents connected to the end of the run.
    pub(super) cycles_per_s: f64,
    pub(super) hash: String,
    pub(super) evicted: Value,
    pub(super) stop_timeouts: u64,
    pub(super) late_stops: u64,
    pub(super) commands_applied: u64,
    /// Per remote agent: its exit code and the last line of its stderr.
    pub(super) agents: Vec<(u32, Option<i32>, String)>,
    /// Per agent: `Ok` when the record holds exactly the commands it logged it sent, in
    /// the cycle it sent them, and it took part in every cycle.
    pub(super) commands: Vec<(u32, Result<(), String>)>,
    /// `agent_evicted` events: (agent, cycle, seconds into the run, reason).
    pub(super) evictions: Vec<Value>,
    /// nftables counters and relay chunks, for the record.
    pub(super) counters: BTreeMap<String, u64>,
    /// Partition: seconds from the link's return until the remote agents answered a
    /// cycle again (`None`: they never did).
    pub(super) resumed_after_s: Option<f64>,
    /// The host's `resumes`: agents back within the resume window after a lost link.
    pub(super) resumes: u64,
    /// Partitions: the host's VmRSS (KiB) once the remote agents answered again after
    /// each one.
    pub(super) rss_kib: Vec<u64>,
}

impl Outcome {
    /// Everything a fault the link recovers from must leave intact: the clean run's
    /// trajectory, every command applied once in its cycle, nobody evicted or timed out.
    pub(super) fn assert_intact(&self, clean: &Outcome) {
        assert_eq!(self.host_code, Some(0), "{self:#?}");
        assert_eq!(self.frames, clean.frames, "{self:#?}");
        assert_eq!(self.hash, clean.hash, "{self:#?}");
        assert_eq!(self.evicted, serde_json::json!([]), "{self:#?}");
        assert!(self.evictions.is_empty(), "{self:#?}");
        assert_eq!(self.stop_timeouts, 0, "{self:#?}");
        assert_eq!(self.late_stops, 0, "{self:#?}");
        assert_eq!(self.commands_applied, clean.commands_applied, "{self:#?}");
        for (id, ok) in &self.commands {
            assert!(ok.is_ok(), "agent {id}: {ok:?}\n{self:#?}");
        }
        for (id, code, last) in &self.agents {
            assert_eq!(*code, Some(0), "agent {id}: {last}");
        }
    }

    /// The `netfaults:` line.
    pub(super) fn report(&self, clean: Option<&Outcome>) {
        let ratio = clean.map_or(String::new(), |c| {
            format!(
                " ({:.2}x the clean link's {:.1})",
                c.cycles_per_s / self.cycles_per_s.max(1e-9),
                c.cycles_per_s
            )
        });
        let hash = match clean {
            Some(c) if c.hash == self.hash => "clean run's hash",
            Some(_) => "hash DIFFERS from the clean run's",
            None => "reference hash",
        };
        let commands = if self.commands.iter().all(|(_, r)| r.is_ok()) {
            "every command applied once".to_string()
        } else {
            self.commands
                .iter()
                .filter_map(|(id, r)| r.as_ref().err().map(|e| format!("agent {id}: {e}")))
                .collect::<Vec<_>>()
                .join("; ")
        };
        let agents = self
            .agents
            .iter()
            .map(|(id, code, last)| {
                format!(
                    "agent {id} exit {code:?}{}",
                    if last.is_empty() {
                        String::new()
                    } else {
                        format!(" ({last})")
                    }
                )
            })
            .collect::<Vec<_>>()
            .join(", ");
        let evictions = self
            .evictions
            .iter()
            .map(|e| {
                format!(
                    "agent {} evicted at cycle {} ({:.1} s, {})",
                    e["agent"],
                    e["cycle"],
                    e["wall_s"].as_f64().unwrap_or(0.0),
                    e["reason"].as_str().unwrap_or("")
                )
            })
            .collect::<Vec<_>>()
            .join(", ");
        let partitioned = matches!(
            self.fault,
            Fault::Partition { .. } | Fault::Partitions { .. } | Fault::OneWay { .. }
        );
        let resumed = match (partitioned, self.resumed_after_s) {
            (true, Some(s)) => format!(
                "; remote agents answered again {s:.1} s after the link returned (the last); host VmRSS after each partition {:?} KiB",
                self.rss_kib
            ),
            (true, None) => "; remote agents never answered again".into(),
            _ => String::new(),
        };
        eprintln!(
            "netfaults: {} {} (lease {} s): host exit {:?}, {} cycles, {:.1} cycles/s{ratio}, {hash}, {commands}, \
             stop timeouts {}, late stops {}, evicted {}{}{}, resumes {}; {agents}; counters {:?}{resumed}",
            self.remote.name(),
            self.fault.label(),
            self.lease_s,
            self.host_code,
            self.frames,
            self.cycles_per_s,
            self.stop_timeouts,
            self.late_stops,
            self.evicted,
            if evictions.is_empty() { "" } else { ": " },
            evictions,
            self.resumes,
            self.counters,
        );
    }
}

/// `Ok` when agent `id` logged every cycle `0..frames` and the host's record holds, for
/// each, exactly the action ids the agent logged it sent then, with the outcome
/// `stopped`: every command applied once, in the cycle it was sent for.
pub(super) fn commands_applied_once(
    rec: &[Value],
    log: &Path,
    id: u32,
    frames: u64,
) -> Result<(), String> {
    let sent: BTreeMap<u64, Vec<u32>> = if log.exists() {
        cycle_log(log)
            .into_iter()
            .map(|l| (l.cycle, l.action_ids))
            .collect()
    } else {
        BTreeMap::new()
    };
    let applied: BTreeMap<u64, (Vec<u32>, String)> = rec
        .iter()
        .filter(|e| e["agent"] == id)
        .map(|e| {
            let ids = e["commands"]
                .as_array()
                .into_iter()
                .flatten()
                .map(|c| c[1].as_u64().expect("action id") as u32)
                .collect();
            (
                e["cycle"].as_u64().expect("cycle"),
                (ids, e["outcome"].as_str().unwrap_or("").to_string()),
            )
        })
        .collect();
    let mut missing = Vec::new();
    for cycle in 0..frames {
        let ok = match (sent.get(&cycle), applied.get(&cycle)) {
            (Some(s), Some((a, outcome))) => s == a && outcome == "stopped",
            _ => false,
        };
        if !ok {
            missing.push(cycle);
        }
    }
    if missing.is_empty() {
        return Ok(());
    }
    let first = missing[0];
    Err(format!(
        "{} of {frames} cycles without exactly the commands sent (first: cycle {first}, sent {:?}, recorded {:?}; cycles logged {}, recorded {})",
        missing.len(),
        sent.get(&first),
        applied.get(&first),
        sent.len(),
        applied.len()
    ))
}
