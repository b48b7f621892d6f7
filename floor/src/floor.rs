//! The floors themselves (see the crate doc).

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::time::{Duration, Instant};

use iceoryx2::port::listener::Listener;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event as event_factory, publish_subscribe as ps_factory};
use vrsync_transport::shm::{POLL_WINDOW_MAX, PollLength, WakeWord, wait_events};

type Svc = ipc::Service;

/// Why a floor measurement failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FloorError {
    /// iceoryx2 refused.
    #[error("iceoryx2: {0}")]
    Iceoryx(String),
    /// A socket failed.
    #[error("tcp: {0}")]
    Io(#[from] std::io::Error),
    /// zenoh refused.
    #[error("zenoh: {0}")]
    Zenoh(String),
    /// Agents did not answer in time.
    #[error("floor agents did not answer within {} s", .0.as_secs_f64())]
    Timeout(Duration),
}

fn ice(what: &str, e: impl core::fmt::Debug) -> FloorError {
    FloorError::Iceoryx(format!("{what}: {e:?}"))
}

fn name(session: &str, suffix: &str) -> Result<ServiceName, FloorError> {
    ServiceName::new(&format!("vrsync-floor/{session}/{suffix}"))
        .map_err(|e| ice("service name", e))
}

/// The floor's wake word's key: its own, beside any vrsync session of the same name.
fn wake_key(session: &str) -> String {
    format!("vrsync-floor/{session}")
}

/// Reads the first and last byte of every row of every image, as the benchmark agent does.
/// Returns a checksum so the reads cannot be optimised away.
pub fn touch_rows(bytes: &[u8], row_len: usize) -> u64 {
    if row_len == 0 {
        return 0;
    }
    let mut sum = 0u64;
    for row in bytes.chunks(row_len) {
        sum = sum
            .wrapping_add(u64::from(row[0]))
            .wrapping_add(u64::from(row[row.len() - 1]));
    }
    std::hint::black_box(sum)
}

/// Host side of the shared-memory floor.
pub struct ShmFloorHost {
    _node: Node<Svc>,
    _start_service: event_factory::PortFactory<Svc>,
    wake: WakeWord,
    _back_service: event_factory::PortFactory<Svc>,
    back: Listener<Svc>,
    services: Vec<ps_factory::PortFactory<Svc, [u8], u64>>,
    publishers: Vec<Publisher<Svc, [u8], u64>>,
    frame_bytes: usize,
    spin: bool,
    poll: PollLength,
    seen: Vec<bool>,
}

impl core::fmt::Debug for ShmFloorHost {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ShmFloorHost")
            .field("agents", &self.publishers.len())
            .finish()
    }
}

impl ShmFloorHost {
    /// Creates the floor services of `session` for `agents` agents of `frame_bytes` each.
    ///
    /// # Errors
    /// [`FloorError`].
    pub fn create(
        session: &str,
        agents: u32,
        frame_bytes: usize,
        spin: bool,
        spin_before_block: Duration,
    ) -> Result<Self, FloorError> {
        vrsync_transport::shm::init_iceoryx2_logging();
        let node = NodeBuilder::new()
            .config(vrsync_transport::shm::iceoryx2_config())
            .create::<Svc>()
            .map_err(|e| ice("node", e))?;
        let n = agents as usize;
        let mut services = Vec::with_capacity(n);
        let mut publishers = Vec::with_capacity(n);
        for id in 0..agents {
            let svc = node
                .service_builder(&name(session, &format!("{id}/frame"))?)
                .publish_subscribe::<[u8]>()
                .user_header::<u64>()
                .max_publishers(1)
                .max_subscribers(1)
                .history_size(0)
                .subscriber_max_buffer_size(1)
                .subscriber_max_borrowed_samples(1)
                .enable_safe_overflow(true)
                .create()
                .map_err(|e| ice("frame service", e))?;
            let publisher = svc
                .publisher_builder()
                .initial_max_slice_len(frame_bytes.max(1))
                .allocation_strategy(AllocationStrategy::Static)
                .max_loaned_samples(1)
                .create()
                .map_err(|e| ice("publisher", e))?;
            services.push(svc);
            publishers.push(publisher);
        }
        let back_service = node
            .service_builder(&name(session, "back")?)
            .event()
            .max_listeners(2)
            .max_notifiers(n + 2)
            .max_nodes(n + 4)
            .event_id_max_value(n + 1)
            .create()
            .map_err(|e| ice("back service", e))?;
        let back = back_service
            .listener_builder()
            .create()
            .map_err(|e| ice("listener", e))?;
        // *Start* reaches every agent the way vrsync's shared-memory host sends it: one
        // bump of a wake word (`start` is only the service agents open first).
        let wake = WakeWord::create(&wake_key(session)).map_err(|e| ice("wake word", e))?;
        let start_service = node
            .service_builder(&name(session, "start")?)
            .event()
            .max_nodes(n + 4)
            .create()
            .map_err(|e| ice("start service", e))?;
        Ok(Self {
            _node: node,
            _start_service: start_service,
            wake,
            _back_service: back_service,
            back,
            services,
            publishers,
            frame_bytes,
            spin,
            poll: PollLength::new(spin_before_block),
            seen: vec![false; n],
        })
    }

    /// Waits until every agent subscribed (their listeners exist before their subscribers).
    ///
    /// # Errors
    /// [`FloorError::Timeout`].
    pub fn wait_connected(&mut self, timeout: Duration) -> Result<(), FloorError> {
        use iceoryx2::service::port_factory::PortFactory as _;
        let deadline = Instant::now() + timeout;
        while !self
            .services
            .iter()
            .all(|s| s.dynamic_config().number_of_subscribers() > 0)
        {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(FloorError::Timeout(timeout));
            }
            // Agents notify "back" once connected.
            let _ = wait_events(&self.back, |_| {}, left.min(Duration::from_millis(100)));
        }
        Ok(())
    }

    /// One round trip: a sample to every agent, one wake, every agent's notify back.
    ///
    /// # Errors
    /// [`FloorError`].
    pub fn cycle(&mut self, cycle: u64, timeout: Duration) -> Result<(), FloorError> {
        for p in &self.publishers {
            let mut s = p
                .loan_slice_uninit(self.frame_bytes)
                .map_err(|e| ice("loan", e))?;
            *s.user_header_mut() = cycle;
            // SAFETY: the floor measures transport cost, not content: the agent reads
            // only row ends, which hold whatever bytes the pool chunk had (plain u8, shared
            // memory is never de-initialised); the first loans are zeroed below.
            let s = if cycle == 0 {
                s.write_from_fn(|_| 0)
            } else {
                unsafe { s.assume_init() }
            };
            s.send().map_err(|e| ice("send", e))?;
        }
        self.wake.bump();
        self.seen.fill(false);
        let mut missing = self.seen.len();
        let wait_started = Instant::now();
        let deadline = wait_started + timeout;
        // Poll before sleeping as vrsync does (same waiting strategy).
        let window = self.poll.window(POLL_WINDOW_MAX);
        let mut polling = true;
        while missing > 0 {
            let seen = &mut self.seen;
            let mut mark = |e: EventActivation| {
                let id = e.id.as_value();
                if let Some(s) = seen.get_mut(id)
                    && !*s
                {
                    *s = true;
                    missing -= 1;
                }
            };
            if self.spin || polling {
                let _ = self.back.try_wait(&mut mark);
                if self.spin {
                    std::hint::spin_loop();
                } else {
                    polling = window.pause();
                }
            } else {
                let left = deadline.saturating_duration_since(Instant::now());
                let _ = wait_events(&self.back, &mut mark, left);
            }
            if Instant::now() >= deadline && missing > 0 {
                return Err(FloorError::Timeout(timeout));
            }
        }
        self.poll.record(wait_started.elapsed());
        Ok(())
    }
}

/// How a shared-memory floor agent runs.
#[derive(Debug, Clone, Copy)]
pub struct ShmFloorAgentOptions {
    /// Round trips to run, warm-up included.
    pub cycles: u64,
    /// Round trips not counted for allocations.
    pub warmup: u64,
    /// Bytes per image row (the touch reads both ends of every row).
    pub row_len: usize,
    /// Busy-poll instead of sleeping.
    pub spin: bool,
    /// Without `spin`: poll this long before sleeping.
    pub spin_before_block: Duration,
    /// Give up after this long.
    pub timeout: Duration,
}

/// Agent side of the shared-memory floor: runs until `cycles` round trips are done.
///
/// # Errors
/// [`FloorError`].
pub fn shm_floor_agent(
    session: &str,
    id: u32,
    options: &ShmFloorAgentOptions,
) -> Result<FloorAgentReport, FloorError> {
    let ShmFloorAgentOptions {
        cycles,
        warmup,
        row_len,
        spin,
        spin_before_block,
        timeout,
    } = *options;
    vrsync_transport::shm::init_iceoryx2_logging();
    let node = NodeBuilder::new()
        .config(vrsync_transport::shm::iceoryx2_config())
        .create::<Svc>()
        .map_err(|e| ice("node", e))?;
    let deadline = Instant::now() + timeout;
    let open_retry = |suffix: &str| -> Result<ServiceName, FloorError> { name(session, suffix) };
    let start_name = open_retry("start")?;
    // Kept open while the agent runs (the host created it last: everything else exists).
    let _start_service = loop {
        match node.service_builder(&start_name).event().open() {
            Ok(s) => break s,
            Err(_) if Instant::now() < deadline => std::thread::sleep(Duration::from_millis(5)),
            Err(e) => return Err(ice("open start", e)),
        }
    };
    let frame_service = node
        .service_builder(&name(session, &format!("{id}/frame"))?)
        .publish_subscribe::<[u8]>()
        .user_header::<u64>()
        .open()
        .map_err(|e| ice("open frame", e))?;
    let back_service = node
        .service_builder(&name(session, "back")?)
        .event()
        .open()
        .map_err(|e| ice("open back", e))?;
    let back = back_service
        .notifier_builder()
        .default_event_id(EventId::new(id as usize))
        .create()
        .map_err(|e| ice("notifier", e))?;
    let wake = WakeWord::open(&wake_key(session)).map_err(|e| ice("open wake word", e))?;
    let sub: Subscriber<Svc, [u8], u64> = frame_service
        .subscriber_builder()
        .buffer_size(1)
        .create()
        .map_err(|e| ice("subscriber", e))?;
    let _ = back.notify();
    let mut poll = PollLength::new(spin_before_block);
    let mut sum = 0u64;
    let mut done = 0u64;
    let mut allocs_at_warmup = None;
    while done < cycles {
        if done >= warmup && allocs_at_warmup.is_none() {
            allocs_at_warmup = Some((vrsync_alloc_count::allocations(), done));
        }
        if Instant::now() >= deadline {
            return Err(FloorError::Timeout(timeout));
        }
        if !spin {
            // Poll before sleeping, as vrsync agents do (same waiting strategy).
            let window = poll.window(POLL_WINDOW_MAX);
            while !sub.has_samples().unwrap_or(true) && window.pause() {}
            // The word's value before the last look: a frame sent after it bumped it.
            let seen = wake.value();
            if !sub.has_samples().unwrap_or(true) {
                wake.wait_change(seen, Duration::from_millis(100));
            }
            poll.record(window.elapsed());
        }
        while let Some(sample) = sub.receive().map_err(|e| ice("receive", e))? {
            sum = sum.wrapping_add(touch_rows(sample.payload(), row_len));
            drop(sample);
            back.notify().map_err(|e| ice("notify back", e))?;
            done += 1;
        }
        if spin {
            std::hint::spin_loop();
        }
        if node.wait(Duration::ZERO).is_err() {
            break;
        }
    }
    Ok(FloorAgentReport::new(sum, allocs_at_warmup, done))
}

/// What a floor agent measured.
#[derive(Debug, Clone, Copy)]
pub struct FloorAgentReport {
    /// Checksum of the touched bytes.
    pub checksum: u64,
    /// Allocations per cycle after the warm-up (with a counting global allocator).
    pub allocs_per_cycle: f64,
}

impl FloorAgentReport {
    pub(crate) fn new(checksum: u64, at_warmup: Option<(u64, u64)>, done: u64) -> Self {
        let allocs_per_cycle = match at_warmup {
            Some((a, c)) if done > c => {
                (vrsync_alloc_count::allocations() - a) as f64 / (done - c) as f64
            }
            _ => f64::NAN,
        };
        Self {
            checksum,
            allocs_per_cycle,
        }
    }
}

/// Host side of the TCP floor.
#[derive(Debug)]
pub struct TcpFloorHost {
    listener: TcpListener,
    conns: Vec<TcpStream>,
    frame: Vec<u8>,
}

impl TcpFloorHost {
    /// Listens on `127.0.0.1:0` for `frame_bytes` frames.
    ///
    /// # Errors
    /// [`FloorError::Io`].
    pub fn create(frame_bytes: usize) -> Result<Self, FloorError> {
        Ok(Self {
            listener: TcpListener::bind("127.0.0.1:0")?,
            conns: Vec::new(),
            frame: vec![0u8; frame_bytes],
        })
    }

    /// The address agents connect to.
    ///
    /// # Errors
    /// [`FloorError::Io`].
    pub fn addr(&self) -> Result<SocketAddr, FloorError> {
        Ok(self.listener.local_addr()?)
    }

    /// Accepts `agents` connections.
    ///
    /// # Errors
    /// [`FloorError`].
    pub fn accept(&mut self, agents: u32, timeout: Duration) -> Result<(), FloorError> {
        self.listener.set_nonblocking(false)?;
        let deadline = Instant::now() + timeout;
        while self.conns.len() < agents as usize {
            if Instant::now() >= deadline {
                return Err(FloorError::Timeout(timeout));
            }
            let (s, _) = self.listener.accept()?;
            s.set_nodelay(true)?;
            s.set_read_timeout(Some(timeout))?;
            self.conns.push(s);
        }
        Ok(())
    }

    /// One round trip: the frame bytes to every agent, an 8-byte reply from each.
    ///
    /// # Errors
    /// [`FloorError::Io`].
    pub fn cycle(&mut self, cycle: u64) -> Result<(), FloorError> {
        let n = self.frame.len().min(8);
        self.frame[..n].copy_from_slice(&cycle.to_le_bytes()[..n]);
        for c in &mut self.conns {
            c.write_all(&self.frame)?;
        }
        let mut reply = [0u8; 8];
        for c in &mut self.conns {
            c.read_exact(&mut reply)?;
        }
        Ok(())
    }
}

/// Agent side of the TCP floor.
///
/// # Errors
/// [`FloorError`].
pub fn tcp_floor_agent(
    addr: SocketAddr,
    frame_bytes: usize,
    cycles: u64,
    warmup: u64,
    row_len: usize,
    timeout: Duration,
) -> Result<FloorAgentReport, FloorError> {
    let mut s = TcpStream::connect_timeout(&addr, timeout)?;
    s.set_nodelay(true)?;
    s.set_read_timeout(Some(timeout))?;
    let mut frame = vec![0u8; frame_bytes];
    let mut sum = 0u64;
    let mut allocs_at_warmup = None;
    for cycle in 0..cycles {
        if cycle == warmup {
            allocs_at_warmup = Some((vrsync_alloc_count::allocations(), cycle));
        }
        s.read_exact(&mut frame)?;
        sum = sum.wrapping_add(touch_rows(&frame, row_len));
        s.write_all(&sum.to_le_bytes())?;
    }
    Ok(FloorAgentReport::new(sum, allocs_at_warmup, cycles))
}
