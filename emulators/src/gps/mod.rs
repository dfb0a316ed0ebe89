//! GPS receiver emulation, layered as the rest of the emulators: truth ([`antenna`]: the antenna
//! on the drive) -> receiver errors ([`errors`]) -> the receiver (its epochs, outages and time
//! to first fix, multipath: [`receiver`]) -> NMEA-0183 encoding ([`nmea`]), all pure. The
//! transport (a pty that nav opens exactly as it opens `/dev/ttyUSB0`, stepped on the IMU clock,
//! or a recorded log replayed at its own pace) is an adapter: [`crate::adapters::pty`].

pub mod antenna;
pub mod errors;
pub mod nmea;
pub mod receiver;

pub use antenna::{AntennaTruth, antenna_truth};
pub use errors::{GpsError, GpsErrorParams};
pub use nmea::NmeaWriter;
pub use receiver::{Epoch, GpsReceiver, GpsRun, Observation, ReceiverModel, ReceiverParams};
