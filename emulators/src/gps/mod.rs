//! GPS receiver emulation, layered as the rest of the emulators: truth ([`truth`]: the antenna on
//! the drive) -> receiver errors ([`errors`]) -> the receiver (its epochs, outages and time to
//! first fix, multipath: [`receiver`]) -> NMEA-0183 encoding ([`nmea`]) -> transport ([`pty`]: a
//! pty that nav opens exactly as it opens `/dev/ttyUSB0`, stepped on the IMU clock, or a recorded
//! log replayed at its own pace). Everything but the transport is pure.

pub mod errors;
pub mod nmea;
pub mod pty;
pub mod receiver;
pub mod truth;

pub use errors::{GpsError, GpsErrorParams};
pub use nmea::NmeaWriter;
pub use pty::{
    Delivered, GpsDevice, GpsPty, GpsTxStats, LogLine, PtyError, TAKE_WAIT, parse_log, relink,
    replay,
};
pub use receiver::{Epoch, GpsReceiver, GpsRun, Observation, ReceiverModel, ReceiverParams};
pub use truth::{AntennaTruth, antenna_truth};
