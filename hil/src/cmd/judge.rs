//! `hil judge-server`: recompute other machines' runs (their in-process reference, the replay
//! of nav's recording and its scoring) in a folder they share (`hil::run::offload`).

use anyhow::Result;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// Arguments of `hil judge-server`.
#[derive(clap::Args)]
pub(crate) struct JudgeServerArgs {
    /// The folder the runs share with this machine (they name it in `HIL_JUDGE_SERVER`).
    #[arg(long)]
    dir: PathBuf,
    /// Runs judged at a time (each uses two threads: the reference run and the replay).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u32).range(1..=64))]
    jobs: u32,
}

pub(crate) fn judge_server(a: JudgeServerArgs) -> Result<i32> {
    let stop = Arc::new(AtomicBool::new(false));
    super::emulate::stop_on_signals(Arc::clone(&stop))?;
    eprintln!(
        "judge-server: serving the runs that share {} ({} at a time; HIL_JUDGE_SERVER={0} on their side); stop with Ctrl-C or SIGTERM",
        a.dir.display(),
        a.jobs
    );
    let served = hil::run::offload::serve(&a.dir, a.jobs as usize, &stop)?;
    eprintln!(
        "judge-server: {} runs judged, {} declined",
        served.done, served.declined
    );
    Ok(0)
}
