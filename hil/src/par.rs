//! Independent in-process runs spread over the machine's cores (rayon).

/// `f` over `jobs` on up to `threads` threads (rayon's work stealing: a long run does not hold
/// up the short ones queued behind it), results in the jobs' order. A job that panics yields
/// `on_panic()`.
pub fn map<J: Sync, R: Send>(
    jobs: &[J],
    threads: usize,
    f: impl Fn(&J) -> R + Sync,
    on_panic: impl Fn() -> R + Sync,
) -> Vec<R> {
    use rayon::prelude::*;
    let one = |j: &J| {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| f(j)))
            .unwrap_or_else(|_| on_panic())
    };
    match rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build()
    {
        Ok(pool) => pool.install(|| jobs.par_iter().map(one).collect()),
        // no threads to be had: one after the other
        Err(_) => jobs.iter().map(one).collect(),
    }
}

/// The number of threads to use by default.
pub fn threads() -> usize {
    std::thread::available_parallelism().map_or(2, |n| n.get())
}

#[cfg(test)]
mod tests {
    #[test]
    fn results_keep_the_jobs_order() {
        let jobs: Vec<u32> = (0..10).collect();
        let r = super::map(&jobs, 3, |j| j * 2, || u32::MAX);
        assert_eq!(r, (0..10).map(|j| j * 2).collect::<Vec<_>>());
    }

    #[test]
    fn a_job_that_panics_costs_only_its_own_result() {
        let jobs: Vec<u32> = (0..6).collect();
        let r = super::map(
            &jobs,
            2,
            |&j| {
                assert!(j != 3, "job 3 fails");
                j
            },
            || u32::MAX,
        );
        assert_eq!(r, vec![0, 1, 2, u32::MAX, 4, 5]);
    }
}
