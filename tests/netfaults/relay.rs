//! A delaying TCP relay: what stands in for netem's delay on a kernel without it.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::util::EVENT_DEADLINE;

/// A TCP relay in a network namespace: accepts on `listen`, connects each accepted
/// connection to `upstream`, and forwards every chunk it reads, in each direction, after
/// holding it `delay ± jitter` (uniform; never before the chunk read before it, so the
/// stream keeps its order). Stopped and joined on drop.
pub(super) struct Relay {
    stop: Arc<AtomicBool>,
    threads: Arc<Mutex<Vec<JoinHandle<()>>>>,
    acceptor: Option<JoinHandle<()>>,
    /// Chunks forwarded (both directions).
    pub(super) chunks: Arc<AtomicU64>,
}

/// A small xorshift generator: the relay's jitter (reproducible by seed, no dependency).
struct XorShift(u64);

impl XorShift {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

impl Relay {
    pub(super) fn start(
        ns: &str,
        listen: SocketAddr,
        upstream: SocketAddr,
        delay: Duration,
        jitter: Duration,
    ) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let threads = Arc::new(Mutex::new(Vec::new()));
        let chunks = Arc::new(AtomicU64::new(0));
        let (ready_tx, ready_rx) = mpsc::channel::<Result<(), String>>();
        let netns_path = format!("/run/netns/{ns}");
        let acceptor = {
            let (stop, threads, chunks) = (stop.clone(), threads.clone(), chunks.clone());
            std::thread::spawn(move || {
                // This thread (only) enters the namespace: the sockets it makes live there.
                let listener = match enter_netns(&netns_path).and_then(|()| {
                    let l = TcpListener::bind(listen).map_err(|e| format!("bind {listen}: {e}"))?;
                    l.set_nonblocking(true).map_err(|e| e.to_string())?;
                    Ok(l)
                }) {
                    Ok(l) => {
                        let _ = ready_tx.send(Ok(()));
                        l
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                        return;
                    }
                };
                let mut seed = 0x9e37_79b9_7f4a_7c15_u64;
                while !stop.load(Ordering::Relaxed) {
                    match listener.accept() {
                        Ok((down, _)) => {
                            let Ok(up) = TcpStream::connect(upstream) else {
                                continue;
                            };
                            let _ = down.set_nonblocking(false);
                            for s in [&down, &up] {
                                let _ = s.set_nodelay(true);
                            }
                            let (Ok(down2), Ok(up2)) = (down.try_clone(), up.try_clone()) else {
                                continue;
                            };
                            let mut t = threads.lock().expect("relay threads");
                            for (from, to) in [(down, up2), (up, down2)] {
                                seed = seed.wrapping_add(0x1234_5678_9abc_def1);
                                t.extend(pump(
                                    from,
                                    to,
                                    delay,
                                    jitter,
                                    XorShift(seed),
                                    &stop,
                                    &chunks,
                                ));
                            }
                        }
                        Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                            wait_readable(&listener, Duration::from_millis(100));
                        }
                        Err(_) => break,
                    }
                }
            })
        };
        match ready_rx.recv_timeout(EVENT_DEADLINE) {
            Ok(Ok(())) => {}
            Ok(Err(e)) => panic!("relay: {e}"),
            Err(e) => panic!("relay did not start: {e}"),
        }
        Self {
            stop,
            threads,
            acceptor: Some(acceptor),
            chunks,
        }
    }
}

/// Moves the calling thread into the network namespace at `path` (`/run/netns/NAME`).
fn enter_netns(path: &str) -> Result<(), String> {
    let file = std::fs::File::open(path).map_err(|e| format!("{path}: {e}"))?;
    use std::os::fd::AsRawFd;
    // SAFETY: setns(2) on a file descriptor we own, for this thread only.
    let rc = unsafe { libc::setns(file.as_raw_fd(), libc::CLONE_NEWNET) };
    if rc == 0 {
        Ok(())
    } else {
        Err(format!("setns {path}: {}", std::io::Error::last_os_error()))
    }
}

/// Blocks until `listener` has a connection to accept or `timeout` passed.
fn wait_readable(listener: &TcpListener, timeout: Duration) {
    use std::os::fd::AsRawFd;
    let mut fd = libc::pollfd {
        fd: listener.as_raw_fd(),
        events: libc::POLLIN,
        revents: 0,
    };
    // SAFETY: poll(2) on one valid pollfd.
    unsafe {
        libc::poll(&mut fd, 1, timeout.as_millis() as i32);
    }
}

/// The two threads of one direction of a relayed connection: a reader that stamps each
/// chunk with its release time, a writer that sends it then.
fn pump(
    mut from: TcpStream,
    mut to: TcpStream,
    delay: Duration,
    jitter: Duration,
    mut rng: XorShift,
    stop: &Arc<AtomicBool>,
    chunks: &Arc<AtomicU64>,
) -> [JoinHandle<()>; 2] {
    let (tx, rx) = mpsc::channel::<(Instant, Vec<u8>)>();
    let _ = from.set_read_timeout(Some(Duration::from_millis(100)));
    let stop_r = stop.clone();
    let reader = std::thread::spawn(move || {
        let mut buf = vec![0u8; 64 * 1024];
        let mut last = Instant::now();
        while !stop_r.load(Ordering::Relaxed) {
            match from.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => {
                    let span = jitter.as_micros() as u64 * 2;
                    let offset = if span == 0 {
                        0
                    } else {
                        rng.next() % (span + 1)
                    };
                    let hold = (delay + Duration::from_micros(offset)).saturating_sub(jitter);
                    last = last.max(Instant::now() + hold);
                    if tx.send((last, buf[..n].to_vec())).is_err() {
                        break;
                    }
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) => {}
                Err(_) => break,
            }
        }
        // Dropping `tx` ends the writer once it sent what was read.
    });
    let (stop_w, chunks) = (stop.clone(), chunks.clone());
    let writer = std::thread::spawn(move || {
        loop {
            match rx.recv_timeout(Duration::from_millis(100)) {
                Ok((at, bytes)) => {
                    // The delay itself: this relay exists to hold data back.
                    std::thread::sleep(at.saturating_duration_since(Instant::now()));
                    if to.write_all(&bytes).is_err() {
                        break;
                    }
                    chunks.fetch_add(1, Ordering::Relaxed);
                }
                Err(mpsc::RecvTimeoutError::Timeout) if !stop_w.load(Ordering::Relaxed) => {}
                Err(_) => break,
            }
        }
        let _ = to.shutdown(std::net::Shutdown::Write);
    });
    [reader, writer]
}

impl Drop for Relay {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.acceptor.take() {
            let _ = t.join();
        }
        let threads = std::mem::take(&mut *self.threads.lock().expect("relay threads"));
        for t in threads {
            let _ = t.join();
        }
    }
}
