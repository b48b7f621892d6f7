//! The session's stacked sample (`[transport.shm] stacked_images`): one sample per cycle
//! that holds the payload (images and vectors) of every shared-memory agent, agent after
//! agent in id order, each block [`stack_stride`] bytes from the last. The agents' own
//! sensor samples then carry the header only.
//!
//! A group that drives all of these agents in one process (a vector env) reads every
//! agent's images of a cycle from one sample: camera `c` of all agents is one array
//! `(N, H, W, C)` with the block stride as its first stride, so it needs no copy.
//!
//! The host writes each agent's payload into its block of the cycle's sample through the
//! agent's [`ShmFrameLoan`], publishes the agents' headers as they come, and sends the
//! stacked sample at *start*, before it wakes the agents. An agent pairs its header with
//! the stacked sample of the same cycle ([`ShmAgent::join_stack`]). The stacked service
//! has one subscriber: one process reads the stacked agents.

use std::cell::{Cell, RefCell, UnsafeCell};
use std::rc::Rc;

use super::agent::attr;
use super::*;

/// The stacked service's name (under `vrsync/<session>/`).
pub const STACK_SERVICE: &str = "stacked";
/// Attribute of the stacked service: `<blocks>x<stride>`, the number of stacked agents and
/// the bytes from one block to the next, as the host's config makes them.
pub const ATTR_STACK: &str = "vrsync.stack";
/// Attribute of a stacked agent's sensor service (value `"1"`): its payload is in the
/// stacked sample, not in its own (see [`ShmAgent::join_stack`]).
pub const ATTR_STACKED: &str = "vrsync.stacked";

/// The bytes from one agent's block of the stacked sample to the next: its payload
/// rounded up to [`IMAGE_ALIGN`](crate::wire::IMAGE_ALIGN), so that every block's images
/// are as aligned as in a sample of their own.
pub fn stack_stride(frame_bytes: usize) -> usize {
    frame_bytes
        .max(1)
        .next_multiple_of(crate::wire::IMAGE_ALIGN)
}

/// The block of agent `id` in `config`'s stacked sample: its place among the
/// shared-memory agents (in id order), if the config stacks them and `id` is one.
pub fn stack_index(config: &Config, id: u32) -> Option<usize> {
    if !config.transport.shm.stacked_images {
        return None;
    }
    config
        .agents
        .iter()
        .filter(|a| a.transport == crate::config::TransportKind::Shm)
        .position(|a| a.id == id)
}

/// The number of stacked agents of `config` and the bytes of each one's payload (they
/// are all the same: the config checks it); `None` if the config does not stack.
pub fn stack_shape(config: &Config) -> Option<(usize, usize)> {
    if !config.transport.shm.stacked_images {
        return None;
    }
    let mut shm = config
        .agents
        .iter()
        .filter(|a| a.transport == crate::config::TransportKind::Shm);
    let frame_bytes = shm.clone().next()?.frame_bytes();
    Some((shm.by_ref().count(), frame_bytes))
}

fn stack_attribute(blocks: usize, stride: usize) -> String {
    format!("{blocks}x{stride}")
}

// ---------------------------------------------------------------------------------------
// Host side
// ---------------------------------------------------------------------------------------

/// The host's publisher of the stacked sample.
pub(super) struct HostStack {
    _service: ps_factory::PortFactory<Svc, [u8], u64>,
    publisher: Publisher<Svc, [u8], u64>,
    blocks: usize,
    stride: usize,
    frame_bytes: usize,
    /// Addresses of pool chunks already written once (as `HostAgentPorts::initialised`).
    initialised: Vec<usize>,
    /// This cycle's sample (loaned with the cycle's first stacked agent's frame) and the
    /// blocks lent out, shared with the frame loans; one for the host's life, so that a
    /// cycle allocates nothing but iceoryx2's loan.
    shared: Rc<StackLoan>,
    /// The cycle of the stacked agents' frames published since the last send.
    cycle: Option<u64>,
}

/// The loaned stacked sample of a cycle, shared by the frame loans of its agents.
pub(super) struct StackLoan {
    /// Set and taken by [`HostStack`] only while no block is lent (see `taken`).
    sample: UnsafeCell<Option<SampleMut<Svc, [u8], u64>>>,
    /// The payload's first byte, taken while the sample was exclusively held.
    base: Cell<*mut u8>,
    /// Per block: a frame loan writes it now (at most one at a time).
    taken: Vec<Cell<bool>>,
}

impl StackLoan {
    /// The first block lent out, if one is.
    fn lent(&self) -> Option<usize> {
        self.taken.iter().position(Cell::get)
    }
}

/// One agent's block of a [`StackLoan`], lent to its frame loan.
pub(super) struct StackBlock {
    loan: Rc<StackLoan>,
    index: usize,
    offset: usize,
    len: usize,
}

impl StackBlock {
    /// The block's bytes.
    pub(super) fn bytes_mut(&mut self) -> &mut [u8] {
        // SAFETY: `offset + len` lies within the sample's payload (checked when the block
        // was made), the sample lives as long as `self.loan`, and `taken` admits one
        // block of an index at a time, so no other `&mut` to these bytes exists; blocks
        // of other indices are disjoint (`len <= stride`).
        unsafe { core::slice::from_raw_parts_mut(self.loan.base.get().add(self.offset), self.len) }
    }
}

impl Drop for StackBlock {
    fn drop(&mut self) {
        if let Some(t) = self.loan.taken.get(self.index) {
            t.set(false);
        }
    }
}

impl HostStack {
    /// Creates the stacked service of `config`'s session (none if the config does not
    /// stack, or stacks no agent).
    pub(super) fn create(
        node: &Node<Svc>,
        config: &Config,
    ) -> Result<Option<Self>, ShmHostCreateError> {
        let ice = ShmHostCreateError::Iceoryx;
        let Some((blocks, frame_bytes)) = stack_shape(config).filter(|&(n, _)| n > 0) else {
            return Ok(None);
        };
        let stride = stack_stride(frame_bytes);
        let key = |k: &str| AttributeKey::try_from(k).map_err(|e| ice(format!("{e:?}")));
        let val = |v: &str| AttributeValue::try_from(v).map_err(|e| ice(format!("{e:?}")));
        let attrs = attributes()
            .map_err(ice)?
            .define(&key(ATTR_STACK)?, &val(&stack_attribute(blocks, stride))?)
            .map_err(|e| ice(format!("{e:?}")))?;
        let name = svc_name(&config.session, STACK_SERVICE).map_err(ice)?;
        let builder = super::host::frame_service::<u64>(node, &name);
        let service = builder.create_with_attributes(&attrs).map_err(|e| {
            if e.already_exists() {
                ShmHostCreateError::SessionInUse {
                    session: config.session.clone(),
                    service: service_name(&config.session, STACK_SERVICE),
                }
            } else {
                ice(format!(
                    "cannot create service {}: {e:?}",
                    service_name(&config.session, STACK_SERVICE)
                ))
            }
        })?;
        let publisher = service
            .publisher_builder()
            .initial_max_slice_len(blocks * stride)
            .allocation_strategy(AllocationStrategy::Static)
            .max_loaned_samples(1)
            .create()
            .map_err(|e| ice(format!("cannot create the stacked publisher: {e:?}")))?;
        Ok(Some(Self {
            _service: service,
            publisher,
            blocks,
            stride,
            frame_bytes,
            initialised: Vec::with_capacity(SENSOR_POOL_SAMPLES * 2),
            shared: Rc::new(StackLoan {
                sample: UnsafeCell::new(None),
                base: Cell::new(core::ptr::null_mut()),
                taken: (0..blocks).map(|_| Cell::new(false)).collect(),
            }),
            cycle: None,
        }))
    }

    /// Block `index` of this cycle's sample (loaned now if it is the cycle's first).
    pub(super) fn block(
        &mut self,
        index: usize,
        cycle_agent: u32,
    ) -> Result<StackBlock, HostTransportError> {
        let loan_err = |reason: String| HostTransportError::Loan {
            agent: cycle_agent,
            reason,
        };
        if index >= self.blocks {
            return Err(loan_err(format!(
                "block {index} of a stacked sample of {} agents",
                self.blocks
            )));
        }
        // SAFETY: a shared read of the option; no `&mut` to it exists (only `loan` and
        // `send` make one, within their own bodies).
        if unsafe { (*self.shared.sample.get()).is_none() } {
            self.loan().map_err(loan_err)?;
        }
        let loan = Rc::clone(&self.shared);
        let Some(taken) = loan.taken.get(index) else {
            return Err(loan_err(format!("no block {index}")));
        };
        if taken.replace(true) {
            return Err(loan_err(
                "this cycle's frame of the agent is loaned already (publish or drop it first)"
                    .into(),
            ));
        }
        Ok(StackBlock {
            loan,
            index,
            offset: index * self.stride,
            len: self.frame_bytes,
        })
    }

    /// Loans this cycle's sample into [`Self::shared`] (which holds none, so no block is
    /// lent).
    fn loan(&mut self) -> Result<(), String> {
        let len = self.blocks * self.stride;
        let mut sample = self
            .publisher
            .loan_slice_uninit(len)
            .map_err(|e| format!("cannot loan the stacked sample: {e:?}"))?;
        let addr = sample.payload().as_ptr() as usize;
        if !self.initialised.contains(&addr) {
            // As `ShmHost::loan`: every byte of a pool chunk gets a value once.
            sample.payload_mut().fill(MaybeUninit::new(0));
            if self.initialised.len() < self.initialised.capacity() {
                self.initialised.push(addr);
            }
        }
        // SAFETY: every byte of this chunk was written (above, now or in an earlier loan
        // of the same chunk); shared memory is never de-initialised afterwards.
        let mut sample = unsafe { sample.assume_init() };
        *sample.user_header_mut() = 0;
        self.shared.base.set(sample.payload_mut().as_mut_ptr());
        // SAFETY: the option holds no sample, so no block is lent and nothing refers to
        // it; this is the only reference for the assignment.
        unsafe { *self.shared.sample.get() = Some(sample) };
        Ok(())
    }

    /// Notes that a stacked agent's frame of `cycle` was published: the stacked sample
    /// goes at the next *start*, stamped with that cycle.
    pub(super) fn published(&mut self, cycle: u64) {
        self.cycle = Some(cycle);
    }

    /// Sends this cycle's sample, if a stacked agent's frame was published (a sample whose
    /// frames were all dropped is returned to the pool unsent). Every frame loan of the
    /// cycle must be published or dropped by now.
    pub(super) fn send(&mut self) -> Result<(), HostTransportError> {
        if let Some(held) = self.shared.lent() {
            // The sample stays: the frame may still be published and the cycle started.
            return Err(HostTransportError::Send {
                what: "the stacked sample of this cycle".into(),
                reason: format!(
                    "the frame of stacked agent #{held} is still loaned: publish or drop \
                     every frame of the cycle before start"
                ),
            });
        }
        // SAFETY: no block is lent (checked above), so nothing refers to the sample; this
        // is the only reference for the take.
        let Some(mut sample) = (unsafe { (*self.shared.sample.get()).take() }) else {
            return Ok(());
        };
        self.shared.base.set(core::ptr::null_mut());
        // A sample whose frames were all dropped goes back to the pool unsent.
        let Some(cycle) = self.cycle.take() else {
            return Ok(());
        };
        *sample.user_header_mut() = cycle;
        sample
            .send()
            .map(drop)
            .map_err(|e| HostTransportError::Send {
                what: "the stacked sample".into(),
                reason: format!("{e:?}"),
            })
    }
}

// ---------------------------------------------------------------------------------------
// Agent side
// ---------------------------------------------------------------------------------------

/// A received stacked sample: every stacked agent's payload of one cycle. (The reader
/// keeps a few of these and refills one nobody holds, so that a cycle allocates nothing;
/// one it has released holds no sample: cycle 0, no payload.)
pub struct StackSample {
    sample: Option<Sample<Svc, [u8], u64>>,
}

impl core::fmt::Debug for StackSample {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("StackSample")
            .field("cycle", &self.cycle())
            .field("bytes", &self.payload().len())
            .finish()
    }
}

impl StackSample {
    /// The cycle of the frames it holds.
    pub fn cycle(&self) -> u64 {
        self.sample.as_ref().map_or(0, |s| *s.user_header())
    }

    /// Every block, one after the other.
    pub fn payload(&self) -> &[u8] {
        self.sample.as_ref().map_or(&[], |s| s.payload())
    }
}

/// The reader of a session's stacked sample, shared by the agents of one group
/// (`Rc<RefCell<ShmStack>>`, see [`ShmAgent::join_stack`]): each agent's frame takes its
/// payload from the stacked sample of its cycle.
pub struct ShmStack {
    session: String,
    _node: Node<Svc>,
    _service: ps_factory::PortFactory<Svc, [u8], u64>,
    sub: Subscriber<Svc, [u8], u64>,
    blocks: usize,
    stride: usize,
    frame_bytes: usize,
    /// The samples received and not yet released: a few `Rc`s, each refilled once only
    /// the pool refers to it (at most [`AGENT_BORROWED_FRAMES`] + 1).
    pool: Vec<Rc<StackSample>>,
    /// The pool entry of the newest sample.
    newest: Option<usize>,
}

impl core::fmt::Debug for ShmStack {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ShmStack")
            .field("session", &self.session)
            .field("blocks", &self.blocks)
            .field("stride", &self.stride)
            .finish()
    }
}

/// What the stacked sample of a cycle is.
pub(super) enum StackLookup {
    /// Here it is.
    Found(Rc<StackSample>),
    /// Not sent yet.
    NotYet,
    /// Replaced by a newer cycle's before it was read.
    Gone,
}

/// iceoryx2 node name of the reader of a session's stacked sample.
pub fn stack_node_name(session: &str) -> String {
    format!("vrsync-stack.{session}")
}

impl ShmStack {
    /// Opens the stacked sample of `config`'s session (its host must be up: open it after
    /// connecting one of its agents).
    ///
    /// # Errors
    /// [`AgentConnectError`]: the config does not stack, the host's stacked sample is
    /// shaped otherwise (another config), or another process reads it.
    pub fn open(config: &Config) -> Result<Self, AgentConnectError> {
        let session = &config.session;
        let fail = |detail: String| AgentConnectError::Transport {
            session: session.clone(),
            agent: config
                .agents
                .iter()
                .find(|a| stack_index(config, a.id).is_some())
                .map_or(0, |a| a.id),
            detail,
        };
        let Some((blocks, frame_bytes)) = stack_shape(config).filter(|&(n, _)| n > 0) else {
            return Err(fail(format!(
                "{}: no stacked agents ([transport.shm] stacked_images is off or no agent \
                 is on shared memory)",
                config.source.display()
            )));
        };
        let stride = stack_stride(frame_bytes);
        let node = node(&stack_node_name(session)).map_err(|e| fail(format!("iceoryx2: {e}")))?;
        let name = svc_name(session, STACK_SERVICE).map_err(|e| fail(format!("iceoryx2: {e}")))?;
        let service = node
            .service_builder(&name)
            .publish_subscribe::<[u8]>()
            .user_header::<u64>()
            .open()
            .map_err(|e| {
                fail(if e.does_not_exist() {
                    format!(
                        "the host does not stack the agents' payloads (no service {}): its \
                         config has no [transport.shm] stacked_images = true",
                        service_name(session, STACK_SERVICE)
                    )
                } else {
                    format!("iceoryx2: cannot open the stacked service: {e:?}")
                })
            })?;
        {
            use iceoryx2::service::port_factory::PortFactory as _;
            let host = attr(service.attributes(), ATTR_STACK);
            let ours = stack_attribute(blocks, stride);
            if host != ours {
                return Err(fail(format!(
                    "the host stacks {host} (agents x bytes per agent), this config {ours}: \
                     host and agents read different configs"
                )));
            }
        }
        let sub = service
            .subscriber_builder()
            .buffer_size(SENSOR_QUEUE)
            .create()
            .map_err(|e| {
                fail(if e.port_limit_reached() {
                    "another reader (a group, an agent or another process) reads this \
                     session's stacked sample: drive every stacked agent through one group \
                     in one process"
                        .into()
                } else {
                    format!("iceoryx2: {e:?}")
                })
            })?;
        Ok(Self {
            session: session.clone(),
            _node: node,
            _service: service,
            sub,
            blocks,
            stride,
            frame_bytes,
            pool: Vec::with_capacity(AGENT_BORROWED_FRAMES + 1),
            newest: None,
        })
    }

    /// The session.
    pub fn session(&self) -> &str {
        &self.session
    }

    /// Whether a sample not received yet is waiting.
    pub fn has_sample(&self) -> bool {
        self.sub.has_samples().unwrap_or(true)
    }

    /// The number of stacked agents.
    pub fn blocks(&self) -> usize {
        self.blocks
    }

    /// The bytes from one agent's block to the next.
    pub fn stride(&self) -> usize {
        self.stride
    }

    /// The stacked sample of `cycle`: receives what came since the last look.
    pub(super) fn lookup(&mut self, cycle: u64) -> Result<StackLookup, AgentReceiveError> {
        if self.newest().is_none_or(|s| s.cycle() < cycle) {
            // What nobody holds goes back first, the newest too when a newer one is
            // waiting: it is then replaced, and its borrow would count against the
            // frames the agents may hold.
            let newer_waiting = self.sub.has_samples().unwrap_or(true);
            self.release_idle(newer_waiting);
            match self.sub.receive() {
                Ok(Some(sample)) => self.store(sample),
                Ok(None) => {}
                Err(iceoryx2::port::ReceiveError::ExceedsMaxBorrows) => {
                    return Err(AgentReceiveError::TooManyFramesHeld {
                        max: AGENT_BORROWED_FRAMES,
                    });
                }
                Err(other) => {
                    return Err(AgentReceiveError::Transport(format!(
                        "iceoryx2: the stacked sample: {other:?}"
                    )));
                }
            }
        }
        Ok(match self.newest() {
            Some(s) if s.cycle() == cycle => StackLookup::Found(Rc::clone(s)),
            Some(s) if s.cycle() > cycle => StackLookup::Gone,
            _ => StackLookup::NotYet,
        })
    }

    fn newest(&self) -> Option<&Rc<StackSample>> {
        self.newest.and_then(|i| self.pool.get(i))
    }

    /// Returns the samples nobody but the pool holds to iceoryx2 (the newest only with
    /// `newest_too`).
    fn release_idle(&mut self, newest_too: bool) {
        for (i, rc) in self.pool.iter_mut().enumerate() {
            if (newest_too || Some(i) != self.newest)
                && let Some(s) = Rc::get_mut(rc)
            {
                s.sample = None;
                if Some(i) == self.newest {
                    self.newest = None;
                }
            }
        }
    }

    /// Makes `sample` the newest, in a pool entry nobody else holds if there is one.
    fn store(&mut self, sample: Sample<Svc, [u8], u64>) {
        let newest = self.newest;
        let free = (0..self.pool.len()).find(|&i| {
            Some(i) != newest
                && self
                    .pool
                    .get_mut(i)
                    .and_then(Rc::get_mut)
                    .is_some_and(|s| s.sample.is_none())
        });
        let free = free.or(newest.filter(|&i| {
            self.pool
                .get_mut(i)
                .is_some_and(|rc| Rc::get_mut(rc).is_some())
        }));
        match free.and_then(|i| self.pool.get_mut(i).and_then(Rc::get_mut).map(|s| (i, s))) {
            Some((i, s)) => {
                s.sample = Some(sample);
                self.newest = Some(i);
            }
            None => {
                self.pool.push(Rc::new(StackSample {
                    sample: Some(sample),
                }));
                self.newest = Some(self.pool.len() - 1);
            }
        }
    }

    /// The byte range of block `index` in a stacked sample.
    pub(super) fn block_range(&self, index: usize) -> core::ops::Range<usize> {
        let start = index * self.stride;
        start..start + self.frame_bytes
    }
}

/// A shared [`ShmStack`], as the agents of a group hold it.
pub type SharedStack = Rc<RefCell<ShmStack>>;

#[cfg(test)]
mod tests;
