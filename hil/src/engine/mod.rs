//! The scenario's devices at work: stepped in process driving nav's pipeline ([`inproc`]) or put
//! behind the bus scheduler ([`devices`]); the in-process reference runs a bench run is compared
//! with ([`mod@reference`]), the in-process navigation runs ([`navigate`]) and navigation scored
//! against truth ([`scoring`]); nav's
//! recording read back and replayed through the pipeline ([`recording`]); the faults' schedule
//! ([`faultlog`]) and the truth recording ([`truthrec`]).

pub mod devices;
pub mod faultlog;
pub mod inproc;
pub mod navigate;
pub mod recording;
pub mod reference;
pub mod scoring;
pub mod truthrec;
