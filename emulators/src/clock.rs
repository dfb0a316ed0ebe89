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
}
