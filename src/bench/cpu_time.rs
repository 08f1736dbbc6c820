//! CPU clocks (POSIX `clock_gettime`): the machine the bench runs on is shared, so wall time
//! alone mixes the tool's speed with other work's. Thread CPU time measures one core's work,
//! process CPU time all threads' (rayon's workers included).
//!
//! | clock | counts |
//! | --- | --- |
//! | [`thread_seconds`] | CPU time of the calling thread (`CLOCK_THREAD_CPUTIME_ID`) |
//! | [`process_seconds`] | CPU time of every thread of the process (`CLOCK_PROCESS_CPUTIME_ID`) |

use rustix::time::{clock_gettime, ClockId};

fn seconds(clock: ClockId) -> f64 {
    let t = clock_gettime(clock);
    t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
}

/// CPU seconds the calling thread has run.
pub fn thread_seconds() -> f64 {
    seconds(ClockId::ThreadCPUTime)
}

/// CPU seconds all threads of this process have run.
pub fn process_seconds() -> f64 {
    seconds(ClockId::ProcessCPUTime)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rayon::prelude::*;

    /// A busy loop advances the thread clock by about its wall time (never more), and work on
    /// rayon's threads shows in the process clock but not in the calling thread's.
    #[test]
    fn clocks_count_the_work_of_their_threads() {
        let spin = |seconds: f64| {
            let start = std::time::Instant::now();
            let mut x = 0u64;
            while start.elapsed().as_secs_f64() < seconds {
                x = std::hint::black_box(x.wrapping_add(1));
            }
        };
        let (thread0, wall0) = (thread_seconds(), std::time::Instant::now());
        spin(0.05);
        let (thread1, wall) = (thread_seconds(), wall0.elapsed().as_secs_f64());
        assert!(
            thread1 - thread0 <= wall + 1e-3,
            "{} > {wall}",
            thread1 - thread0
        );
        assert!(thread1 - thread0 > 0.0);

        let (thread0, process0) = (thread_seconds(), process_seconds());
        // Work on rayon's pool only (the calling thread waits), 0.05 s per task.
        rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap()
            .install(|| (0..4).into_par_iter().for_each(|_| spin(0.05)));
        let (thread1, process1) = (thread_seconds(), process_seconds());
        assert!(process1 - process0 > thread1 - thread0);
    }
}
