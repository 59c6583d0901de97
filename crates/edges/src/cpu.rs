//! The calling thread's CPU time: what a stage costs the machine, which other work on it
//! disturbs far less than the wall clock (a thread waiting for a core is not charged).
//!
//! In: nothing. Out: [`thread_cpu_time`], the CPU time the calling thread has used since it
//! started (`clock_gettime(CLOCK_THREAD_CPUTIME_ID)`, user and system; one system call, about
//! a few hundred nanoseconds: read it per phase, not per pixel or per edge).

use std::time::Duration;

/// CPU time (user + system) the calling thread has used so far; zero where the platform has no
/// per-thread clock.
pub fn thread_cpu_time() -> Duration {
    #[cfg(unix)]
    {
        let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: `t` is a valid timespec to write into; the clock id is a constant the kernel
        // knows, and the call writes nothing else.
        if unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) } == 0 {
            return Duration::new(t.tv_sec as u64, t.tv_nsec as u32);
        }
    }
    Duration::ZERO
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The clock moves with work done on this thread (never faster than the wall clock), and
    /// not with sleep. Under load a spinning thread gets only part of a core, so the spin runs
    /// until the clock has charged 10 ms, within a generous wall-clock limit.
    #[test]
    fn the_thread_clock_counts_work_and_not_sleep() {
        let a = thread_cpu_time();
        std::thread::sleep(Duration::from_millis(50));
        let b = thread_cpu_time();
        assert!(b - a < Duration::from_millis(25), "slept 50 ms, charged {:?}", b - a);
        let mut x = 1u64;
        let started = std::time::Instant::now();
        while thread_cpu_time() - b < Duration::from_millis(10) {
            assert!(
                started.elapsed() < Duration::from_secs(20),
                "the clock did not move with work"
            );
            for _ in 0..10_000 {
                x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
            }
        }
        let c = thread_cpu_time();
        let wall = started.elapsed();
        assert!(
            c - b <= wall + Duration::from_millis(1),
            "charged {:?} in {wall:?}",
            c - b
        );
    }
}
