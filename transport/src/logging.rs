//! The default log filter of vrsync's programs and C ABIs.

/// zenoh's events that say nothing to a vrsync user, each silenced below `error`:
/// `zenoh::net::routing::hat::peer` warns "Gossip is disabled: cannot de-duplicate data
/// traversing region gateways" whenever a peer starts with gossip off, which vrsync does
/// on purpose (`transport.zenoh.scouting = false`, the default: host and agents are
/// connected by their endpoints, and there is no region gateway to de-duplicate for).
pub const QUIET_ZENOH: &[&str] = &["zenoh::net::routing::hat::peer=error"];

/// The `RUST_LOG`-style filter text of a program logging at `level` by default (`"info"`,
/// `"warn"`, ...): `level` plus the [`QUIET_ZENOH`] directives. `vr-sim`, `vr-agent` and
/// the C ABIs' `vrs_init_logging` / `vrs_host_init_logging` use it when `RUST_LOG` is
/// unset; a set `RUST_LOG` is used as it is.
pub fn default_log_filter(level: &str) -> String {
    let mut text = level.to_string();
    for directive in QUIET_ZENOH {
        text.push(',');
        text.push_str(directive);
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_filter_is_the_level_and_zenohs_quiet_targets() {
        assert_eq!(
            default_log_filter("info"),
            "info,zenoh::net::routing::hat::peer=error"
        );
        // Every directive parses as a tracing filter directive.
        for d in QUIET_ZENOH {
            d.parse::<tracing_subscriber::filter::Directive>()
                .unwrap_or_else(|e| panic!("{d}: {e}"));
        }
    }
}
