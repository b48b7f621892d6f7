//! The environment socket: connections paired with their client's agent connection, the
//! resets they carry, and the timers that keep strangers from holding its slots.

use super::*;

impl LegacyHost {
    /// Whether environment connection `c`'s agent connection is still the one it was
    /// paired with.
    pub(super) fn env_paired(&self, c: &EnvConn) -> bool {
        c.agent.is_some_and(|(slot, seq)| {
            self.slots
                .get(slot)
                .and_then(|s| s.conn.as_ref())
                .is_some_and(|a| a.seq == seq)
        })
    }

    /// Closes environment connection `k` with a warning naming its peer and `why`, and
    /// reports it as a refused peer of `kind`.
    pub(super) fn close_env(&mut self, k: usize, kind: RefusalKind, why: String) {
        let c = self.env_conns.remove(k);
        let agent = c
            .agent
            .and_then(|(slot, _)| self.slots.get(slot))
            .map(|s| s.id);
        let lost = if c.resets.is_empty() {
            String::new()
        } else {
            format!(
                " ({} resets sent before it was paired dropped)",
                c.resets.len()
            )
        };
        warn!(peer = %c.peer, ?agent, "legacy environment connection closed: {why}{lost}");
        self.refusals.push(PeerRefusal::new(
            kind,
            agent,
            c.peer.to_string(),
            format!("environment socket: {why}"),
        ));
    }

    pub(super) fn accept_env(&mut self) {
        loop {
            match self.env_listener.accept() {
                Ok((stream, peer)) => {
                    if stream.set_nonblocking(true).is_err()
                        || self.watch(stream.as_raw_fd()).is_err()
                    {
                        continue;
                    }
                    // A full cap closes the oldest unpaired connection, not the new one: a
                    // peer holding idle connections cannot lock a client out (issue 22).
                    let unpaired: Vec<usize> = (0..self.env_conns.len())
                        .filter(|&k| !self.env_paired(&self.env_conns[k]))
                        .collect();
                    if unpaired.len() >= MAX_ENV_CONNS {
                        // `env_conns` is in accept order: the first is the oldest.
                        self.close_env(
                            unpaired[0],
                            RefusalKind::TooMany,
                            format!(
                                "{MAX_ENV_CONNS} connections without an agent connection are \
                                 open; the oldest makes room for {peer}"
                            ),
                        );
                    }
                    debug!(%peer, "legacy environment connection");
                    self.env_conns.push(EnvConn {
                        stream,
                        peer,
                        reader: FrameReader::new(MAX_ENV_FRAME),
                        seq: self.next_seq,
                        agent: None,
                        unpaired_since: Instant::now(),
                        partial_since: None,
                        resets: Vec::new(),
                    });
                    self.next_seq += 1;
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => {
                    if e.kind() != ErrorKind::WouldBlock {
                        warn!("legacy accept on the environment socket failed: {e}");
                    }
                    break;
                }
            }
        }
    }

    pub(super) fn read_env(&mut self) {
        let mut i = 0;
        while i < self.env_conns.len() {
            let (max_commands, stall_timeout) = (self.max_commands, self.stall_timeout);
            let c = &mut self.env_conns[i];
            let mut drop_why = None;
            for _ in 0..MAX_FRAMES_PER_PASS {
                let r = c.reader.read_from(&mut c.stream);
                if let Some(n) = c.reader.oversize() {
                    drop_why = Some((
                        Some(RefusalKind::Malformed),
                        format!(
                            "it announced a frame of {n} bytes; the environment socket carries \
                             only resets (at most {MAX_ENV_FRAME} bytes)"
                        ),
                    ));
                    break;
                }
                match r {
                    Ok(FrameProgress::Frame) => {
                        c.partial_since = None;
                        // Fields 11 and 12 are the same in both dialects.
                        match codec::decode_frame(c.reader.body(), Dialect::Burkhardt) {
                            Ok(Incoming::Reset(cmd)) => {
                                if c.resets.len() < max_commands {
                                    c.resets.push(cmd.encode(RESET_ACTION_ID));
                                } else {
                                    warn!(peer = %c.peer, "legacy reset dropped: {} are waiting already", c.resets.len());
                                }
                            }
                            Ok(other) => {
                                debug!(peer = %c.peer, ?other, "legacy environment socket: message ignored (only resets are read there)");
                            }
                            Err(e) => {
                                self.stats.frames_refused += 1;
                                warn!(peer = %c.peer, "legacy environment frame refused: {e}");
                            }
                        }
                    }
                    Ok(FrameProgress::Skipped(n)) => {
                        drop_why = Some((
                            Some(RefusalKind::Malformed),
                            format!("it sent a frame of {n} bytes (at most {MAX_ENV_FRAME})"),
                        ));
                        break;
                    }
                    Ok(FrameProgress::Pending) => {
                        if c.reader.mid_frame() {
                            let now = Instant::now();
                            let since = *c.partial_since.get_or_insert(now);
                            if now.duration_since(since) >= stall_timeout {
                                drop_why = Some((
                                    Some(RefusalKind::Malformed),
                                    format!(
                                        "stalled mid-frame: {} within {}",
                                        c.reader.progress(),
                                        Rounded(stall_timeout)
                                    ),
                                ));
                            }
                        }
                        break;
                    }
                    Ok(FrameProgress::Closed) => {
                        if c.reader.mid_frame() {
                            drop_why = Some((
                                Some(RefusalKind::Malformed),
                                format!(
                                    "closed mid-frame after {} (truncated frame not applied)",
                                    c.reader.progress()
                                ),
                            ));
                        } else {
                            drop_why = Some((None, String::new()));
                        }
                        break;
                    }
                    Err(e) => {
                        drop_why = Some((Some(RefusalKind::Malformed), e.to_string()));
                        break;
                    }
                }
            }
            let Some((kind, why)) = drop_why else {
                i += 1;
                continue;
            };
            // Resets it sent before it went still go to its agent.
            self.route_env(i);
            match kind {
                Some(kind) => self.close_env(i, kind, why),
                None => {
                    let c = self.env_conns.remove(i);
                    if c.resets.is_empty() {
                        debug!(peer = %c.peer, "legacy environment connection closed by its client");
                    } else {
                        warn!(peer = %c.peer, "legacy environment connection closed by its client before it was paired with an agent connection: its {} resets are dropped", c.resets.len());
                    }
                }
            }
        }
    }

    /// Ends the life of unpaired environment connections: one whose client's agent
    /// connection did not pass its version check within the hello timeout of it (or whose
    /// agent connection went away that long ago) is closed.
    pub(super) fn expire_env(&mut self) {
        let now = Instant::now();
        let mut k = 0;
        while k < self.env_conns.len() {
            let paired = self.env_paired(&self.env_conns[k]);
            let c = &mut self.env_conns[k];
            if !paired && c.agent.take().is_some() {
                c.unpaired_since = now;
            }
            if !paired && now.duration_since(c.unpaired_since) >= self.hello_timeout {
                let why = format!(
                    "no agent connection of the same client passed its version check within {} \
                     (resets go to the agent whose client sent them)",
                    Rounded(self.hello_timeout)
                );
                self.close_env(k, RefusalKind::Silent, why);
            } else {
                k += 1;
            }
        }
    }

    /// Hands the resets read on environment connection `k` to its paired agent, in whose
    /// batch they are applied; unpaired, they wait (see [`LegacyHost::pair_env`]).
    pub(super) fn route_env(&mut self, k: usize) {
        if !self.env_paired(&self.env_conns[k]) || self.env_conns[k].resets.is_empty() {
            return;
        }
        let Some((slot, _)) = self.env_conns[k].agent else {
            return;
        };
        let mut resets = std::mem::take(&mut self.env_conns[k].resets);
        for cmd in resets.drain(..) {
            Self::queue_command(&mut self.slots[slot], cmd, self.sync_mode);
        }
        // Keep the buffer.
        self.env_conns[k].resets = resets;
    }

    pub(super) fn route_resets(&mut self) {
        for k in 0..self.env_conns.len() {
            self.route_env(k);
        }
    }

    /// Pairs the agent connection of slot `i` (which has just passed its version check)
    /// with the environment connection of the same client, whose resets then go to this
    /// agent. The wire carries no identity; the original clients connect the environment
    /// socket first and their agent socket right after, from one process. So the rule:
    /// among the environment connections not paired yet, from the same IP address and
    /// accepted before this agent connection, the newest one; where the host can see
    /// which process owns the client sockets (a peer on this machine, run by the same
    /// user: `/proc/net/tcp` and `/proc/<pid>/fd`), one of the agent's own process, else
    /// one whose process is unknown. A client that connects no environment socket
    /// (`agentOnly`) gets none.
    pub(super) fn pair_env(&mut self, i: usize) {
        let Some(a) = &self.slots[i].conn else {
            return;
        };
        let (a_seq, a_peer) = (a.seq, a.peer);
        let mut candidates: Vec<usize> = (0..self.env_conns.len())
            .filter(|&k| {
                let c = &self.env_conns[k];
                c.seq < a_seq && c.peer.ip() == a_peer.ip() && !self.env_paired(c)
            })
            .collect();
        if candidates.is_empty() {
            debug!(agent = self.slots[i].id, peer = %a_peer, "legacy agent connection without an environment connection");
            return;
        }
        // Newest first.
        candidates.sort_by_key(|&k| std::cmp::Reverse(self.env_conns[k].seq));
        let mut sockets = vec![(a_peer, a.stream.local_addr().ok())];
        sockets.extend(candidates.iter().map(|&k| {
            let c = &self.env_conns[k];
            (c.peer, c.stream.local_addr().ok())
        }));
        let owners = socket_owners(&sockets);
        let theirs = || candidates.iter().zip(owners.iter().skip(1));
        let pick = match owners.first().copied().flatten() {
            Some(pid) => theirs()
                .find(|(_, o)| **o == Some(pid))
                .or_else(|| theirs().find(|(_, o)| o.is_none()))
                .map(|(&k, _)| k),
            None => candidates.first().copied(),
        };
        let Some(k) = pick else {
            debug!(agent = self.slots[i].id, peer = %a_peer, "legacy agent connection: no environment connection of its process");
            return;
        };
        let c = &mut self.env_conns[k];
        c.agent = Some((i, a_seq));
        info!(agent = self.slots[i].id, agent_peer = %a_peer, env_peer = %c.peer, "legacy environment connection paired: its resets go to this agent");
    }
}

/// The processes owning the client ends of accepted connections `(peer, local)` (the
/// host's accepted socket has local address `local` and peer `peer`; the client's socket
/// is the one bound to `peer` and connected to `local`), where the host can see them: a
/// client on this machine, in this network namespace, run by the same user (or the host
/// is privileged). `None` where it cannot. Reads `/proc/net/tcp{,6}` once and walks
/// `/proc/<pid>/fd` once; called only when an agent connection passes its version check.
pub(super) fn socket_owners(conns: &[(SocketAddr, Option<SocketAddr>)]) -> Vec<Option<u32>> {
    let mut inodes: Vec<Option<u64>> = vec![None; conns.len()];
    for table in ["/proc/net/tcp", "/proc/net/tcp6"] {
        let Ok(text) = std::fs::read_to_string(table) else {
            continue;
        };
        for line in text.lines().skip(1) {
            let f: Vec<&str> = line.split_whitespace().collect();
            let (Some(local), Some(remote), Some(inode)) = (
                f.get(1).and_then(|a| proc_addr(a)),
                f.get(2).and_then(|a| proc_addr(a)),
                f.get(9).and_then(|i| i.parse::<u64>().ok()),
            ) else {
                continue;
            };
            for (k, (peer, host)) in conns.iter().enumerate() {
                let host = host.map(canonical);
                if inode != 0 && local == canonical(*peer) && Some(remote) == host {
                    inodes[k] = Some(inode);
                }
            }
        }
    }
    let mut owners: Vec<Option<u32>> = vec![None; conns.len()];
    let mut left = inodes.iter().filter(|i| i.is_some()).count();
    let Ok(procs) = std::fs::read_dir("/proc") else {
        return owners;
    };
    for entry in procs.flatten() {
        if left == 0 {
            break;
        }
        let Some(pid) = entry
            .file_name()
            .to_str()
            .and_then(|n| n.parse::<u32>().ok())
        else {
            continue;
        };
        let Ok(fds) = std::fs::read_dir(entry.path().join("fd")) else {
            continue;
        };
        for fd in fds.flatten() {
            let Ok(target) = std::fs::read_link(fd.path()) else {
                continue;
            };
            let Some(inode) = target
                .to_str()
                .and_then(|t| t.strip_prefix("socket:["))
                .and_then(|t| t.strip_suffix(']'))
                .and_then(|t| t.parse::<u64>().ok())
            else {
                continue;
            };
            for (k, want) in inodes.iter().enumerate() {
                if *want == Some(inode) && owners[k].is_none() {
                    owners[k] = Some(pid);
                    left -= 1;
                }
            }
        }
    }
    owners
}

/// `addr` with a v4-mapped IPv6 address (a v4 peer of a dual-stack socket) as IPv4.
pub(super) fn canonical(addr: SocketAddr) -> SocketAddr {
    match addr.ip() {
        IpAddr::V6(v6) => v6
            .to_ipv4_mapped()
            .map_or(addr, |v4| SocketAddr::new(v4.into(), addr.port())),
        IpAddr::V4(_) => addr,
    }
}

/// An address of `/proc/net/tcp{,6}`: the IP's 32-bit words in hex as stored (native
/// byte order), a colon, the port in hex.
pub(super) fn proc_addr(text: &str) -> Option<SocketAddr> {
    let (ip, port) = text.split_once(':')?;
    let port = u16::from_str_radix(port, 16).ok()?;
    let word = |k: usize| -> Option<[u8; 4]> {
        let w = u32::from_str_radix(ip.get(8 * k..8 * k + 8)?, 16).ok()?;
        Some(w.to_ne_bytes())
    };
    let ip: IpAddr = match ip.len() {
        8 => std::net::Ipv4Addr::from(word(0)?).into(),
        32 => {
            let mut b = [0u8; 16];
            for k in 0..4 {
                b[4 * k..4 * k + 4].copy_from_slice(&word(k)?);
            }
            std::net::Ipv6Addr::from(b).into()
        }
        _ => return None,
    };
    Some(canonical(SocketAddr::new(ip, port)))
}
