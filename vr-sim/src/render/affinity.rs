//! Binding the render threads to CPUs.
//!
//! Waking a sleeping thread does not make it run in parallel with its waker everywhere: a
//! kernel may put the woken thread on the waker's CPU while another CPU idles (measured
//! on a 2-vCPU KVM guest that packs tasks onto few vCPUs: at 64 agents the second render
//! thread waited the whole 1.2 ms render behind the first, on the same vCPU, while the
//! other vCPU was idle). A thread bound to one CPU runs there. So when the pool has one
//! thread per CPU the process may use, each thread is bound to its own
//! ([`Affinity::Auto`]).

use std::io;

/// Whether the render pool's threads are each bound to one CPU.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Affinity {
    /// Bind when there is one render thread per CPU this process may use (the default
    /// thread count), else let the kernel place them.
    #[default]
    Auto,
    /// Bind render thread i to the i-th CPU this process may use (round robin).
    Bind,
    /// Let the kernel place the render threads.
    Free,
}

impl Affinity {
    /// The CPUs to bind the pool's `threads` threads to (thread `i` to `cpus[i %
    /// len]`), or none.
    pub(crate) fn cpus_for(self, threads: usize) -> Option<Vec<usize>> {
        if self == Self::Free || threads < 2 {
            return None;
        }
        let cpus = allowed_cpus().ok()?;
        match self {
            Self::Auto if cpus.len() != threads => None,
            _ if cpus.is_empty() => None,
            _ => Some(cpus),
        }
    }
}

/// The CPUs the calling thread may run on, in increasing order.
///
/// # Errors
/// The OS error of `sched_getaffinity`; on other systems than Linux, `Unsupported`.
pub fn allowed_cpus() -> io::Result<Vec<usize>> {
    #[cfg(target_os = "linux")]
    {
        // SAFETY: a zeroed `cpu_set_t` is a valid empty set; `sched_getaffinity` writes at
        // most `size_of::<cpu_set_t>()` bytes into it.
        let set = unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            if libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) != 0 {
                return Err(io::Error::last_os_error());
            }
            set
        };
        let max = 8 * std::mem::size_of::<libc::cpu_set_t>();
        // SAFETY: `cpu` is below the set's size in bits.
        Ok((0..max)
            .filter(|&cpu| unsafe { libc::CPU_ISSET(cpu, &set) })
            .collect())
    }
    #[cfg(not(target_os = "linux"))]
    {
        Err(io::Error::new(
            io::ErrorKind::Unsupported,
            "CPU affinity is only set on Linux",
        ))
    }
}

/// Binds the calling thread to `cpu`.
///
/// # Errors
/// The OS error of `sched_setaffinity` (e.g. `cpu` is not allowed); on other systems than
/// Linux, `Unsupported`.
pub fn bind_current_thread(cpu: usize) -> io::Result<()> {
    #[cfg(target_os = "linux")]
    {
        let max = 8 * std::mem::size_of::<libc::cpu_set_t>();
        if cpu >= max {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("CPU {cpu} is beyond the {max} a CPU set holds"),
            ));
        }
        // SAFETY: as in `allowed_cpus`; `cpu` is below the set's size in bits; pid 0 is the
        // calling thread.
        let rc = unsafe {
            let mut set: libc::cpu_set_t = std::mem::zeroed();
            libc::CPU_SET(cpu, &mut set);
            libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
        };
        if rc == 0 {
            Ok(())
        } else {
            Err(io::Error::last_os_error())
        }
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = cpu;
        Err(io::Error::new(
            io::ErrorKind::Unsupported,
            "CPU affinity is only set on Linux",
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_thread_bound_to_an_allowed_cpu_may_run_there_only() {
        let cpus = allowed_cpus().unwrap();
        assert!(!cpus.is_empty());
        assert!(cpus.windows(2).all(|w| w[0] < w[1]));
        let last = *cpus.last().unwrap();
        let seen = std::thread::spawn(move || {
            bind_current_thread(last).unwrap();
            allowed_cpus().unwrap()
        })
        .join()
        .unwrap();
        assert_eq!(seen, vec![last]);
        // The calling thread is unchanged.
        assert_eq!(allowed_cpus().unwrap(), cpus);
    }

    #[test]
    fn a_bound_render_pool_has_each_thread_on_its_cpu_and_a_free_one_anywhere() {
        let cpus = allowed_cpus().unwrap();
        // Each pool thread's CPU mask, by thread index.
        let masks = |affinity| {
            let r = crate::render::Renderer::with_affinity(3, affinity).unwrap();
            r.pool
                .as_ref()
                .unwrap()
                .broadcast(|_| allowed_cpus().unwrap())
        };
        let want: Vec<Vec<usize>> = (0..3).map(|i| vec![cpus[i % cpus.len()]]).collect();
        assert_eq!(masks(Affinity::Bind), want);
        assert_eq!(masks(Affinity::Free), vec![cpus.clone(); 3]);
    }

    #[test]
    fn binding_to_a_cpu_beyond_a_set_is_an_error() {
        let err = bind_current_thread(1 << 20).unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::InvalidInput);
    }

    #[test]
    fn auto_binds_a_pool_of_one_thread_per_cpu_only() {
        let n = allowed_cpus().unwrap().len();
        assert_eq!(Affinity::Free.cpus_for(n), None);
        assert_eq!(Affinity::Auto.cpus_for(1), None);
        assert_eq!(Affinity::Bind.cpus_for(1), None);
        if n >= 2 {
            assert_eq!(Affinity::Auto.cpus_for(n), Some(allowed_cpus().unwrap()));
            assert_eq!(Affinity::Auto.cpus_for(n + 1), None);
        }
        assert_eq!(
            Affinity::Bind.cpus_for(n + 1),
            Some(allowed_cpus().unwrap())
        );
    }
}
