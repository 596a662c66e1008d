//! Keeping rayon's threads awake through a solve of a large graph.
//!
//! A solve alternates short parallel passes (the linearization and the
//! assembly, a few milliseconds each on a pose graph of a few thousand
//! edges) with long serial ones (the sparse factorization, tens of
//! milliseconds). Between passes rayon's idle threads go to sleep, and each
//! pass waits for them to wake. On the two-vCPU virtual machines of the
//! benchmarks that took milliseconds: in sphere2500's linearization passes
//! (2–3.5 ms), the second thread took its first task 1.2–3.0 ms after the
//! pass began, or not at all. OpenMP runtimes keep idle threads polling for
//! work for a while for the same reason (`OMP_WAIT_POLICY`, `KMP_BLOCKTIME`).
//!
//! Here the solve runs on a thread of rayon's pool, and each of the pool's
//! other threads polls for the solve's parallel work until the solve ends,
//! napping [`POLL_INTERVAL`] between polls: its core stays free for any
//! other thread, and the naps are too short for the core to be given up.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// A poller's nap between polls. Short beside a parallel pass (2–3.5 ms on
/// sphere2500), so work waits at most ~2 % of a pass for it; long beside a
/// poll (about a microsecond), so a poller uses little of its core. Polling
/// by `sched_yield` instead was no faster and spent 0.8–0.9 s of system
/// time in seven sphere2500 solves (0.1 s with the naps).
const POLL_INTERVAL: Duration = Duration::from_micros(50);

/// Sets the flag when dropped: the pollers stop even where the solve panics
/// (the scope waits for them before it propagates the panic).
struct StopOnDrop<'a>(&'a AtomicBool);

impl Drop for StopOnDrop<'_> {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Release);
    }
}

/// Set while a solve keeps the pool awake. One at a time: a poller takes up
/// whatever work reaches the pool, and a second solve run inside the first
/// one's poller would hold the first one's end back until it finished.
static POOL_KEPT_AWAKE: AtomicBool = AtomicBool::new(false);

/// Releases [`POOL_KEPT_AWAKE`] when dropped.
struct Release;

impl Drop for Release {
    fn drop(&mut self) {
        POOL_KEPT_AWAKE.store(false, Ordering::Release);
    }
}

/// Run `solve`, and return its result, on a thread of rayon's global pool
/// while the pool's other threads poll for work instead of sleeping (see
/// the module doc). Runs it on the calling thread, as without this, where
/// the pool has one thread, where the caller is in the pool (a poller could
/// take up the caller's other jobs and hold the solve's end back until they
/// finish) or where another solve keeps the pool awake.
pub(super) fn run_keeping_pool_awake<R: Send>(solve: impl FnOnce() -> R + Send) -> R {
    let outside_pool = rayon::current_thread_index().is_none() && rayon::current_num_threads() > 1;
    if !outside_pool || POOL_KEPT_AWAKE.compare_exchange(false, true, Ordering::AcqRel, Ordering::Acquire).is_err() {
        return solve();
    }
    let _release = Release;
    let stop = AtomicBool::new(false);
    rayon::scope(|scope| {
        let (stop, solver_thread) = (&stop, rayon::current_thread_index());
        let _stop = StopOnDrop(stop);
        for _ in 1..rayon::current_num_threads() {
            scope.spawn(move |_| {
                // The solve's own thread may take this job up while it waits
                // for a parallel pass: it must return to the solve at once.
                if rayon::current_thread_index() == solver_thread {
                    return;
                }
                while !stop.load(Ordering::Acquire) {
                    if rayon::yield_now() != Some(rayon::Yield::Executed) {
                        std::thread::sleep(POLL_INTERVAL);
                    }
                }
            });
        }
        solve()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;

    /// One test: the flag is shared by the whole process.
    #[test]
    fn solves_run_and_return_while_the_pool_polls_and_a_panic_stops_the_pollers() {
        let expect: u64 = (0..100_000u64).map(|i| i % 7).sum();
        let solve = || {
            let sum = (0..100_000u64).into_par_iter().map(|i| i % 7).sum::<u64>();
            // A solve nested in another one's runs on the calling thread.
            let nested = run_keeping_pool_awake(|| (0..1000u32).into_par_iter().sum::<u32>());
            (rayon::current_thread_index().is_some(), sum, nested)
        };
        // Alone: on the pool, where it has more than one thread.
        let alone = std::thread::spawn(move || run_keeping_pool_awake(solve)).join().expect("no panic");
        assert_eq!(alone, (rayon::current_num_threads() > 1, expect, 499_500));
        // Several at once from plain threads, as tests and applications call
        // `Optimizer::optimize`: each returns its result.
        let threads: Vec<_> = (0..3).map(|_| std::thread::spawn(move || run_keeping_pool_awake(solve))).collect();
        for t in threads {
            let (_, sum, nested) = t.join().expect("no panic");
            assert_eq!((sum, nested), (expect, 499_500));
        }
        assert!(!POOL_KEPT_AWAKE.load(Ordering::Acquire), "released");
        // A panicking solve: the pollers stop, the flag is released, the
        // pool runs new work.
        let result = std::panic::catch_unwind(|| run_keeping_pool_awake(|| panic!("solve failed")));
        assert!(result.is_err());
        assert!(!POOL_KEPT_AWAKE.load(Ordering::Acquire), "released after the panic");
        assert_eq!((0..1000u32).into_par_iter().sum::<u32>(), 499_500);
    }
}
