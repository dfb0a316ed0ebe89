//! The order in which nav's shell hands its pipeline the CAN frames and the receiver's bytes:
//! the order they arrived, by the kernel's receive time of each frame against the time just
//! before each read of the receiver's port.
//!
//! A frame's receive time is taken as the kernel queues it (`netif_rx`), and the frame reaches
//! the socket later, when the receive softirq runs; a loaded machine defers that work to
//! `ksoftirqd`. So a frame stamped before a read can still be on its way when the read
//! returns, and bytes taken at once would go in before it. The bytes wait instead, each read
//! until a frame stamped after it has been received (the frames before it, queued earlier on
//! the same path, are then in the socket). An IMU that has stopped sends no later frame: then
//! the bytes go in when nav's IMU watchdog fires, before its report (the shell releases them
//! all), or at the latest when their own wait ends, as long as the watchdog's timeout (a run
//! that never heard its IMU). No shorter wall-time limit: a loaded machine that stalls the
//! bench for a tenth of a second must not move the bytes ahead of a frame still on its way
//! (which changes the sample at which nav confirms them in NAV_TIME); a stall as long as the
//! watchdog is already a starved run, reported as one. Pure: the shell (`nav`'s binary) reads
//! the socket and the port and does what [`Waiting::order`] says.

use std::collections::VecDeque;
use std::ops::Range;
use std::time::{Duration, Instant};

/// One read of the receiver's port, not yet taken.
#[derive(Debug, Clone, PartialEq)]
pub struct Read {
    /// Wall time just before the read, ns since the epoch.
    pub t_ns: u64,
    /// The bytes read.
    pub bytes: Vec<u8>,
    /// When it goes in whatever came: the read's time plus the wait ([`Waiting::new`]).
    pub until: Instant,
}

/// Which waiting reads go in after the frames given to [`Waiting::order`], besides those a
/// later frame releases.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Release {
    /// None.
    Ordered,
    /// Those whose wait ends at or before this instant (oldest first, up to the first that
    /// does not).
    Expired(Instant),
    /// All (a port event, the end of the run, a socket without receive times).
    All,
}

/// What the shell hands the pipeline, in order.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// These frames of the batch given, in their order.
    Frames(Range<usize>),
    /// A read's bytes.
    Bytes(Read),
}

/// The receiver's reads that wait for the frames sent before them, oldest first.
#[derive(Debug)]
pub struct Waiting {
    reads: VecDeque<Read>,
    wait: Duration,
    expired: u64,
}

impl Waiting {
    /// No read waiting; each read to come waits at most `wait` for a frame received after it
    /// (nav's IMU watchdog timeout).
    pub fn new(wait: Duration) -> Self {
        Waiting {
            reads: VecDeque::new(),
            wait,
            expired: 0,
        }
    }

    /// A read of `bytes` that began at `t_ns` (ns since the epoch), at `now`.
    pub fn push(&mut self, t_ns: u64, bytes: Vec<u8>, now: Instant) {
        self.reads.push_back(Read {
            t_ns,
            bytes,
            until: now + self.wait,
        });
    }

    /// Reads that went in because their wait ended, no frame after them having come
    /// ([`Release::Expired`]): none in a lockstep run whose IMU never stopped for longer than
    /// the wait.
    pub fn expired(&self) -> u64 {
        self.expired
    }

    /// No read waits.
    pub fn is_empty(&self) -> bool {
        self.reads.is_empty()
    }

    /// When the oldest waiting read goes in at the latest.
    pub fn deadline(&self) -> Option<Instant> {
        self.reads.front().map(|r| r.until)
    }

    /// A batch of frames received (their kernel receive times, ns since the epoch, in the
    /// order received; none where the socket gives none) with the waiting reads among them:
    /// a read goes in before the first frame stamped after it, every frame stamped at or
    /// before it (ties included) ahead of it, as `hil replay --bus` puts them back. Reads
    /// keep their order. After the batch, what `release` lets go.
    pub fn order(
        &mut self,
        stamps: impl IntoIterator<Item = Option<u64>>,
        release: Release,
    ) -> Vec<Step> {
        let mut steps = Vec::new();
        let mut start = 0;
        let mut n = 0;
        for (i, stamp) in stamps.into_iter().enumerate() {
            n = i + 1;
            let Some(s) = stamp else { continue };
            while let Some(r) = self.reads.pop_front_if(|r| s > r.t_ns) {
                if i > start {
                    steps.push(Step::Frames(start..i));
                    start = i;
                }
                steps.push(Step::Bytes(r));
            }
        }
        if n > start {
            steps.push(Step::Frames(start..n));
        }
        while let Some(r) = self.reads.pop_front_if(|r| match release {
            Release::Ordered => false,
            Release::Expired(now) => r.until <= now,
            Release::All => true,
        }) {
            if matches!(release, Release::Expired(_)) {
                self.expired += 1;
            }
            steps.push(Step::Bytes(r));
        }
        steps
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const WAIT: Duration = Duration::from_millis(100);

    /// Each step as the frames' range or the bytes.
    type Seen<'a> = Vec<(Option<Range<usize>>, Option<&'a [u8]>)>;

    fn bytes(steps: &[Step]) -> Seen<'_> {
        steps
            .iter()
            .map(|s| match s {
                Step::Frames(r) => (Some(r.clone()), None),
                Step::Bytes(b) => (None, Some(b.bytes.as_slice())),
            })
            .collect()
    }

    /// A read waits for a frame stamped after it: frames stamped before it (one still on
    /// its way when it was read) go first, ties included; several reads keep their order and
    /// go in each before the first frame after it; a frame without a stamp releases nothing.
    #[test]
    fn a_read_goes_in_before_the_first_frame_stamped_after_it() {
        let now = Instant::now();
        let mut w = Waiting::new(WAIT);
        w.push(100, b"a".to_vec(), now);
        // nothing after it yet: the frames already in the socket go, the read waits
        let s = w.order([Some(90), Some(95)], Release::Ordered);
        assert_eq!(bytes(&s), vec![(Some(0..2), None)]);
        assert!(!w.is_empty());
        // the frame stamped before the read arrives late, then one after it
        w.push(200, b"b".to_vec(), now);
        let s = w.order(
            [Some(99), Some(100), None, Some(150), Some(201), Some(300)],
            Release::Ordered,
        );
        assert_eq!(
            bytes(&s),
            vec![
                (Some(0..3), None),
                (None, Some(b"a".as_slice())),
                (Some(3..4), None),
                (None, Some(b"b".as_slice())),
                (Some(4..6), None),
            ]
        );
        assert!(w.is_empty() && w.deadline().is_none());
        assert_eq!(w.expired(), 0);
        // two reads released by one frame, in their order, before it
        w.push(10, b"c".to_vec(), now);
        w.push(20, b"d".to_vec(), now);
        let s = w.order([Some(30)], Release::Ordered);
        assert_eq!(
            bytes(&s),
            vec![
                (None, Some(b"c".as_slice())),
                (None, Some(b"d".as_slice())),
                (Some(0..1), None)
            ]
        );
    }

    /// Without a later frame a read goes in when its wait ends, or at once when all go; only
    /// those whose wait has ended, oldest first.
    #[test]
    fn a_read_goes_in_when_its_wait_ends_or_when_all_go() {
        let t0 = Instant::now();
        let mut w = Waiting::new(WAIT);
        w.push(100, b"a".to_vec(), t0);
        w.push(200, b"b".to_vec(), t0 + WAIT);
        assert_eq!(w.deadline(), Some(t0 + WAIT));
        assert_eq!(w.order([], Release::Expired(t0 + WAIT / 2)), vec![]);
        let s = w.order([Some(50)], Release::Expired(t0 + WAIT));
        assert_eq!(
            bytes(&s),
            vec![(Some(0..1), None), (None, Some(b"a".as_slice()))]
        );
        assert_eq!(w.deadline(), Some(t0 + 2 * WAIT));
        let s = w.order([None], Release::All);
        assert_eq!(
            bytes(&s),
            vec![(Some(0..1), None), (None, Some(b"b".as_slice()))]
        );
        assert!(w.is_empty());
        assert_eq!(w.expired(), 1, "one read went in by its wait, one with all");
    }
}
