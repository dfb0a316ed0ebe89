//! The simulated clock shared by all emulators, paced against wall time by a speed factor.

use std::time::{Duration, Instant};

/// Simulated time paced at `speed` x real time from a wall-clock origin.
#[derive(Debug, Clone, Copy)]
pub struct SimClock {
    origin: Instant,
    speed: f64,
}

impl SimClock {
    /// Start a clock now. `speed` 1.0 is real time; 10.0 runs ten times faster.
    pub fn start(speed: f64) -> Self {
        Self {
            origin: Instant::now(),
            speed: speed.max(1e-6),
        }
    }

    /// A clock whose simulated time 0 is the host's instant `origin` (devices started apart
    /// share one clock by sharing it).
    pub fn starting_at(origin: Instant, speed: f64) -> Self {
        Self {
            origin,
            speed: speed.max(1e-6),
        }
    }

    /// Speed factor.
    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// The wall instant at which simulated time `t` (s) is due.
    pub fn wall_at(&self, t: f64) -> Instant {
        self.origin + Duration::from_secs_f64((t / self.speed).max(0.0))
    }

    /// Simulated time now, s.
    pub fn now(&self) -> f64 {
        self.origin.elapsed().as_secs_f64() * self.speed
    }

    /// When simulated time `t` is already overdue (the stream runs behind the wall clock), move
    /// the origin so that `t` is due now: what follows is then paced from here, not caught up at
    /// once. Used where a silence must last its paced wall time (an IMU that stops sending for
    /// seconds must look stopped to a watchdog, however far behind the stream was). Returns how
    /// far behind it was, s of wall time (0 when it was not).
    pub fn catch_up(&mut self, t: f64) -> f64 {
        let due = self.wall_at(t);
        let now = Instant::now();
        if due >= now {
            return 0.0;
        }
        let behind = now - due;
        self.origin += behind;
        behind.as_secs_f64()
    }

    /// Sleep until simulated time `t` is due (returns at once when it already is).
    pub fn sleep_until(&self, t: f64) {
        let due = self.wall_at(t);
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speed_scales_wall_time() {
        let c = SimClock::start(10.0);
        assert_eq!(c.wall_at(10.0) - c.wall_at(0.0), Duration::from_secs(1));
        c.sleep_until(0.2);
        let t = c.now();
        assert!((0.2..0.5).contains(&t), "{t}");
    }

    #[test]
    fn catching_up_paces_what_follows_from_now() {
        let mut c = SimClock::start(10.0);
        std::thread::sleep(Duration::from_millis(50));
        // 0.5 s of simulated time is overdue by about 50 ms: after catching up it is due now
        let behind = c.catch_up(0.0);
        assert!((0.04..0.5).contains(&behind), "{behind}");
        let before = Instant::now();
        c.sleep_until(1.0);
        let slept = before.elapsed().as_secs_f64();
        assert!((0.09..0.5).contains(&slept), "{slept}");
        // not behind: nothing moves
        assert_eq!(c.catch_up(100.0), 0.0);
    }
}
