//! The adapters: what puts the pure models on real devices and paces them by the wall clock.
//! The bus scheduler that drives every device on vcan in lockstep with nav ([`scheduler`]),
//! the socket transport and the bench's log of what it sent ([`transport`]), the receiver's
//! pty ([`pty`]), the player of a recording ([`player`]), the free-running devices on the
//! host's clock ([`freerun`]) and that clock ([`clock`]). Nothing outside this folder imports
//! it: the models, the bus model and the step order are pure (tests/tests/layout.rs).

pub mod clock;
pub mod fd;
pub mod freerun;
pub mod player;
pub mod pty;
pub mod scheduler;
pub mod transport;
