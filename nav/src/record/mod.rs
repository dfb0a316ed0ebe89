//! nav's recording: the MCAP writer on its own thread, the raw traffic's recorded form, the
//! JSON channels and Foxglove's views of them.

pub mod channels;
pub mod foxglove;
pub mod raw;
pub mod writer;
