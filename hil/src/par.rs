//! Independent in-process runs spread over the machine's cores.

/// `f` over `jobs` on up to `threads` threads, results in the jobs' order. A worker that
/// panics yields `on_panic()` for each of its jobs.
pub fn map<J: Sync, R: Send>(
    jobs: &[J],
    threads: usize,
    f: impl Fn(&J) -> R + Sync,
    on_panic: impl Fn() -> R + Sync,
) -> Vec<R> {
    let chunk = jobs.len().div_ceil(threads.max(1)).max(1);
    std::thread::scope(|sc| {
        let handles: Vec<_> = jobs
            .chunks(chunk)
            .map(|part| {
                let f = &f;
                (
                    part.len(),
                    sc.spawn(move || part.iter().map(f).collect::<Vec<_>>()),
                )
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|(n, h)| {
                h.join()
                    .unwrap_or_else(|_| (0..n).map(|_| on_panic()).collect())
            })
            .collect()
    })
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
}
