//! The faults a case puts on the agents' side of the link.

/// A fault on the agents' side of the link.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Fault {
    Clean,
    /// `percent` % of the TCP packets dropped, each direction.
    Loss {
        percent: u32,
    },
    /// Everything dropped from when the remote agents logged `at_cycle`, for `secs`.
    Partition {
        at_cycle: u64,
        secs: u64,
    },
    /// The packets towards one side dropped from when the remote agents logged
    /// `at_cycle`, for `secs`: that side's lease runs out, the other's does not.
    OneWay {
        at_cycle: u64,
        secs: u64,
        towards: Towards,
    },
    /// `percent` % of the TCP packets dropped each way from when the remote agents logged
    /// `at_cycle` to the end of the run (its end happens under loss).
    LossFrom {
        at_cycle: u64,
        percent: u32,
    },
    /// `count` partitions of `secs` in a row: the first from when the remote agents logged
    /// `at_cycle`, each next one `every` cycles after the cycle the last one ended in.
    Partitions {
        at_cycle: u64,
        every: u64,
        secs: u64,
        count: u64,
    },
    /// `percent` % of the packets sent twice, each direction.
    Duplicate {
        percent: u32,
    },
    /// Each direction of the byte stream held `ms ± jitter_ms` ([`super::Relay`]).
    Delay {
        ms: u64,
        jitter_ms: u64,
    },
    /// `percent` % of the packets each way sent through a slower path ([`super::Reorder`]).
    Reorder {
        percent: u32,
    },
}

/// The side whose packets a one-way partition drops (the packets towards it).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Towards {
    Host,
    Agents,
}

impl Fault {
    pub(super) fn label(self) -> String {
        match self {
            Self::Clean => "clean".into(),
            Self::Loss { percent } => format!("loss {percent}%"),
            Self::Partition { at_cycle, secs } => format!("partition {secs}s at cycle {at_cycle}"),
            Self::OneWay {
                at_cycle,
                secs,
                towards,
            } => format!("one-way partition towards the {towards:?} {secs}s at cycle {at_cycle}"),
            Self::LossFrom { at_cycle, percent } => {
                format!("loss {percent}% from cycle {at_cycle} to the end")
            }
            Self::Partitions {
                at_cycle,
                every,
                secs,
                count,
            } => {
                format!("{count} partitions of {secs}s from cycle {at_cycle}, {every} cycles apart")
            }
            Self::Duplicate { percent } => format!("duplicate {percent}%"),
            Self::Delay { ms, jitter_ms } => format!("delay {ms}±{jitter_ms}ms"),
            Self::Reorder { percent } => format!("reorder {percent}%"),
        }
    }
}
