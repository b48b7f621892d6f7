//! The TCP host's connections before they are agents: accepting them, reading their
//! hellos, admitting or refusing them, and re-attaching an agent that is back within its
//! resume window.

use super::*;
use crate::rounded::Rounded;
use crate::wait;
use crate::{PeerRefusal, RefusalKind};

impl TcpHost {
    pub(super) fn accept_new(&mut self) {
        let mut turned_away = 0usize;
        loop {
            match self.listener.accept() {
                Ok((stream, peer)) => {
                    if self.pending.len() >= MAX_PENDING {
                        // Closed at once: a flood of silent connections costs a bounded
                        // number of descriptors and buffers.
                        debug!(%peer, "TCP peer dropped: too many connections waiting for their hello");
                        turned_away += 1;
                        continue;
                    }
                    if stream.set_nonblocking(true).is_err()
                        || set_nodelay(&stream).is_err()
                        || self
                            .poll
                            .add(stream.as_raw_fd(), stream.as_raw_fd() as u64)
                            .is_err()
                    {
                        continue;
                    }
                    debug!(%peer, "TCP connection");
                    self.pending.push(Pending {
                        stream,
                        peer,
                        since: Instant::now(),
                        reader: RecordReader::new(MAX_HELLO),
                        hello: None,
                    });
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => {
                    warn!("TCP accept failed: {e}");
                    break;
                }
            }
        }
        if turned_away > 0 {
            self.refusals.count(turned_away as u64);
            warn!(
                "TCP peer dropped: {turned_away} connection(s) closed at once, {MAX_PENDING} are already waiting for their hello"
            );
        }
    }

    /// Whether a complete hello must wait before it is admitted: its id's connection is
    /// closed by its peer (the agent left, died or reconnects) but not read to its end. Its
    /// last records (a stop, a leave batch) and its loss belong to the cycle the host
    /// waits for, and the host must see the old connection go before a new one of the
    /// same id counts as connected: else it would wait for a stop the new connection
    /// never got a frame for. The host's next drain reads the old connection to its end;
    /// the wait after it admits the new one. A host that does not drain within
    /// [`HELLO_TIMEOUT`] (it waits for agents, not for stops) gets the new connection
    /// anyway, the old one dropped with what it still held.
    fn must_defer(&self, hello: &Hello) -> bool {
        self.slots
            .iter()
            .find(|s| s.id == hello.agent_id)
            .and_then(|s| s.conn.as_ref())
            .is_some_and(|c| wait::peer_closed(c.stream.as_raw_fd()))
    }

    /// Admits the deferred hellos whose id's old connection is gone, or that waited
    /// [`HELLO_TIMEOUT`]. Returns whether one was admitted.
    fn admit_deferred(&mut self) -> bool {
        let mut admitted = false;
        let mut i = 0;
        while i < self.pending.len() {
            let Some(hello) = &self.pending[i].hello else {
                i += 1;
                continue;
            };
            let gone = !self
                .slots
                .iter()
                .any(|s| s.id == hello.agent_id && s.conn.is_some());
            if gone || self.pending[i].since.elapsed() >= HELLO_TIMEOUT {
                let mut p = self.pending.swap_remove(i);
                if let Some(hello) = p.hello.take() {
                    self.admit(p, hello);
                    admitted = true;
                }
            } else {
                i += 1;
            }
        }
        admitted
    }

    /// Reads pending hellos; admits, rejects or times out each connection.
    pub(super) fn handle_pending(&mut self) {
        // A deferred hello whose predecessor the host has let go since is admitted now.
        self.admit_deferred();
        let mut i = 0;
        while i < self.pending.len() {
            if self.pending[i].hello.is_some() {
                i += 1;
                continue;
            }
            match self.progress_hello(i) {
                Ok(None) => {
                    let p = &self.pending[i];
                    if p.since.elapsed() >= HELLO_TIMEOUT {
                        let why = if p.reader.buffered() == 0 {
                            format!(
                                "sent nothing within {} of connecting (no hello)",
                                Rounded(HELLO_TIMEOUT)
                            )
                        } else {
                            format!(
                                "stalled mid-record: {} of its hello within {} of connecting",
                                p.reader.progress(),
                                Rounded(HELLO_TIMEOUT)
                            )
                        };
                        let p = self.pending.swap_remove(i);
                        self.refuse(RefusalKind::Silent, None, p.peer, why);
                    } else {
                        i += 1;
                    }
                }
                Ok(Some(hello)) if self.must_defer(&hello) => {
                    // It waits for the host's next drain, not for its socket.
                    let fd = self.pending[i].stream.as_raw_fd();
                    let _ = self.poll.set_readable(fd, fd as u64, false);
                    self.pending[i].hello = Some(hello);
                    i += 1;
                }
                Ok(Some(hello)) => {
                    let p = self.pending.swap_remove(i);
                    self.admit(p, hello);
                }
                Err((why, closed)) => {
                    let mut p = self.pending.swap_remove(i);
                    let kind = if closed {
                        RefusalKind::Silent
                    } else {
                        RefusalKind::Malformed
                    };
                    self.refuse(kind, None, p.peer, why.clone());
                    if !closed {
                        let _ = p.stream.set_nonblocking(false);
                        let _ = p.stream.set_write_timeout(Some(Duration::from_millis(200)));
                        let _ = write_record(
                            &mut p.stream,
                            kind::REJECT,
                            &Reject::new(reject::MALFORMED, why.as_str()).encode(),
                        );
                    }
                }
            }
        }
    }

    /// Reads what has arrived of connection `i`'s hello. `Err((why, closed))` drops it.
    fn progress_hello(&mut self, i: usize) -> Result<Option<Hello>, (String, bool)> {
        let p = &mut self.pending[i];
        match p.reader.read_from(&mut p.stream) {
            Ok(ReadProgress::Record(kind::HELLO)) => decode_hello(p.reader.body())
                .map(Some)
                .map_err(|e| (e.to_string(), false)),
            Ok(ReadProgress::Record(k)) => {
                Err((format!("expected a hello, got record kind {k}"), false))
            }
            Ok(ReadProgress::Pending) => match p.reader.head() {
                // Refuse a wrong kind as soon as its prefix is in.
                Some((_, k)) if k != kind::HELLO => {
                    Err((format!("expected a hello, got record kind {k}"), false))
                }
                _ => Ok(None),
            },
            Ok(ReadProgress::Closed) if p.reader.buffered() == 0 => {
                Err(("closed the connection without a hello".into(), true))
            }
            Ok(ReadProgress::Closed) => Err((
                format!(
                    "closed the connection mid-record after {} of its hello",
                    p.reader.progress()
                ),
                true,
            )),
            Err(e) => Err((e.to_string(), false)),
        }
    }

    /// Logs and records a refused peer.
    fn refuse(&mut self, kind: RefusalKind, agent: Option<u32>, peer: SocketAddr, why: String) {
        match agent {
            Some(agent) => warn!(%peer, agent, "TCP agent refused: {why}"),
            None => warn!(%peer, "TCP peer dropped: {why}"),
        }
        self.refusals.push(PeerRefusal {
            kind,
            agent,
            peer: peer.to_string(),
            reason: why,
        });
    }

    /// Tells a peer why its hello is refused (best effort), then logs and records it.
    fn refuse_hello(&mut self, stream: &mut TcpStream, peer: SocketAddr, agent: u32, r: Reject) {
        let _ = stream.set_nonblocking(false);
        let _ = stream.set_write_timeout(Some(Duration::from_millis(200)));
        let _ = write_record(stream, kind::REJECT, &r.encode());
        self.refuse(RefusalKind::of_reject(r.code), Some(agent), peer, r.message);
    }

    fn admit(&mut self, p: Pending, hello: Hello) {
        let mut stream = p.stream;
        let peer = p.peer;
        let agent = hello.agent_id;
        let served: Vec<u32> = self.slots.iter().map(|s| s.id).collect();
        let slot = match admit(
            &hello,
            self.token.as_deref(),
            "wrong tcp_token",
            &served,
            &self.layouts,
        ) {
            Ok(slot) => slot,
            Err(r) => return self.refuse_hello(&mut stream, peer, agent, r),
        };
        if let Some(old) = &self.slots[slot].conn
            && wait::peer_closed(old.stream.as_raw_fd())
        {
            // The agent died or reconnects; its old connection is gone already.
            self.drop_conn(
                slot,
                "connection closed (a new connection takes its place)",
                Loss::Lost,
            );
        }
        if self.slots[slot].conn.is_some() {
            return self.refuse_hello(&mut stream, peer, agent, Reject::id_in_use(agent));
        }
        let mut welcome = [0u8; 16];
        welcome[..4].copy_from_slice(&PROTOCOL_VERSION.to_le_bytes());
        welcome[4..12].copy_from_slice(&LAYOUT_HASH.to_le_bytes());
        welcome[12..].copy_from_slice(&(self.slots[slot].body_len as u32).to_le_bytes());
        let sent = stream
            .set_nonblocking(false)
            .and_then(|()| stream.set_write_timeout(Some(Duration::from_secs(1))))
            .and_then(|()| write_record(&mut stream, kind::WELCOME, &welcome))
            .and_then(|()| stream.set_nonblocking(true));
        if let Err(e) = sent {
            warn!(peer = %p.peer, "TCP agent lost during welcome: {e}");
            return;
        }
        // Watched like the other agents' sockets (a deferred hello's socket was muted).
        let fd = stream.as_raw_fd();
        if let Err(e) = self.poll.set_readable(fd, fd as u64, !self.muted) {
            warn!(peer = %p.peer, "TCP agent lost during welcome: epoll: {e}");
            return;
        }
        if !self.resume_window.is_zero()
            && let Err(e) = watch_link(&stream)
        {
            warn!(peer = %p.peer, "TCP agent's link is not watched: {e}");
        }
        info!(agent = hello.agent_id, peer = %p.peer, "TCP agent connected");
        self.slots[slot].conn = Some(Conn {
            stream,
            peer: p.peer,
            reader: RecordReader::new(self.max_motor_body),
            partial_since: None,
        });
        if let Some(held) = self.slots[slot].resuming.take() {
            self.resume(slot, held.since);
        }
    }

    /// Re-attaches agent `slot`, back on a new connection within the resume window: the
    /// frame the host published last goes out again unless its stop arrived (the agent
    /// then sends that stop again if it had sent it before the link went).
    pub(super) fn resume(&mut self, slot: usize, since: Instant) {
        let deadline = Instant::now() + self.write_timeout;
        self.resumed += 1;
        let s = &mut self.slots[slot];
        info!(
            agent = s.id,
            down_s = since.elapsed().as_secs_f64(),
            "TCP agent back within the resume window: resumed"
        );
        let (Some(c), Some(buf), Some(cycle)) = (&mut s.conn, &s.buf, s.published) else {
            return;
        };
        if s.stopped.is_some_and(|stopped| stopped >= cycle) {
            return;
        }
        if let Err(e) = Self::send_all(&mut c.stream, buf.record(), deadline) {
            self.drop_conn(
                slot,
                &format!("cannot send its frame again: {e}"),
                loss_of(&e),
            );
        }
    }
}
